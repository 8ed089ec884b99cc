"""Writes a vehicle of the shared data (../shared/data/ekf) as a ROS bag with PyPI rosbags,
as a robot's drivers would have logged it, for `chassisd import`.

usage: write_bag.py husky|comma DATA_DIR ros1|ros2 OUT START_NS [TOPIC,...]

With TOPICs, only those topics are written (a bag that lacks the others).

husky: /gps/fix (sensor_msgs/NavSatFix, the receiver's status and covariance), /imu/data
(sensor_msgs/Imu, as mounted), /husky_velocity_controller/odom (nav_msgs/Odometry).
comma: /ublox/fix (NavSatFix, no covariance), /ublox/fix_velocity
(geometry_msgs/TwistWithCovarianceStamped, x east, y north), /phone/imu (Imu, axes forward,
right, down), /wheels/odom (Odometry from the rear wheels over a 1.57 m track).

Stamps are START_NS plus each sample's time since the data's first sample, so a recording
of the bag shares its times with one made from the CSV by chassisd's own converter (which
starts the data 3 s after its START).
"""

import csv
import math
import sys
from pathlib import Path

from rosbags.typesys import Stores, get_typestore

store = get_typestore(Stores.ROS1_NOETIC if sys.argv[3] == "ros1" else Stores.ROS2_JAZZY)
T = store.types
ROS1 = sys.argv[3] == "ros1"


def rows(path, *names):
    with open(path) as f:
        return [[float(r[n]) for n in names] for r in csv.DictReader(f)]


def stamp(ns):
    Time = T["builtin_interfaces/msg/Time"]
    return Time(sec=ns // 10**9, nanosec=ns % 10**9)


def header(ns, frame):
    Header = T["std_msgs/msg/Header"]
    if ROS1:
        return Header(seq=0, stamp=stamp(ns), frame_id=frame)
    return Header(stamp=stamp(ns), frame_id=frame)


def vec(x=0.0, y=0.0, z=0.0):
    return T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def quat(x=0.0, y=0.0, z=0.0, w=1.0):
    return T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)


def zeros(n):
    import numpy
    return numpy.zeros(n, dtype=numpy.float64)


def array(values):
    import numpy
    return numpy.array(values, dtype=numpy.float64)


def navsatfix(ns, status, lat, lon, alt, cov, cov_type):
    return T["sensor_msgs/msg/NavSatFix"](
        header=header(ns, "gps"),
        status=T["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
        latitude=lat, longitude=lon, altitude=alt,
        position_covariance=array(cov), position_covariance_type=cov_type)


def imu(ns, wx, wy, wz):
    return T["sensor_msgs/msg/Imu"](
        header=header(ns, "imu_link"), orientation=quat(), orientation_covariance=zeros(9),
        angular_velocity=vec(wx, wy, wz), angular_velocity_covariance=zeros(9),
        linear_acceleration=vec(), linear_acceleration_covariance=zeros(9))


def odometry(ns, vx, wz):
    P = T["geometry_msgs/msg/PoseWithCovariance"]
    Tw = T["geometry_msgs/msg/TwistWithCovariance"]
    return T["nav_msgs/msg/Odometry"](
        header=header(ns, "odom"), child_frame_id="base_link",
        pose=P(pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                                  orientation=quat()), covariance=zeros(36)),
        twist=Tw(twist=T["geometry_msgs/msg/Twist"](linear=vec(vx), angular=vec(z=wz)),
                 covariance=zeros(36)))


def velocity(ns, east, north):
    Tw = T["geometry_msgs/msg/TwistWithCovariance"]
    return T["geometry_msgs/msg/TwistWithCovarianceStamped"](
        header=header(ns, "gps"),
        twist=Tw(twist=T["geometry_msgs/msg/Twist"](linear=vec(east, north), angular=vec()),
                 covariance=zeros(36)))


def husky(data):
    gps = rows(data / "gps.csv", "t", "status", "latitude", "longitude", "altitude",
               "pos_cov_xx", "pos_cov_yy", "pos_cov_zz", "position_covariance_type")
    imus = rows(data / "imu.csv", "t", "wx", "wy", "wz")
    odom = rows(data / "odom.csv", "t", "vx", "wz")
    t0 = min(gps[0][0], imus[0][0], odom[0][0])
    out = []
    for g in gps:
        cov = [g[5], 0, 0, 0, g[6], 0, 0, 0, g[7]]
        out.append(("/gps/fix", "sensor_msgs/msg/NavSatFix", g[0] - t0,
                    lambda ns, g=g, cov=cov: navsatfix(ns, int(g[1]), g[2], g[3], g[4], cov, int(g[8]))))
    for i in imus:
        out.append(("/imu/data", "sensor_msgs/msg/Imu", i[0] - t0, lambda ns, i=i: imu(ns, *i[1:])))
    for o in odom:
        out.append(("/husky_velocity_controller/odom", "nav_msgs/msg/Odometry", o[0] - t0,
                    lambda ns, o=o: odometry(ns, o[1], o[2])))
    return out


def comma(data):
    wheels = rows(data / "wheel_speed.csv", "t", "rear_left_mps", "rear_right_mps")
    gyro = rows(data / "imu.csv", "t", "gyro_x", "gyro_y", "gyro_z")
    gnss = rows(data / "gnss.csv", "t", "latitude", "longitude", "altitude_m", "speed_mps",
                "bearing_deg")
    end = rows(data / "reference.csv", "t")[-1][0]
    t0 = min(wheels[0][0], gyro[0][0], gnss[0][0])
    out = []
    for g in gnss:
        out.append(("/ublox/fix", "sensor_msgs/msg/NavSatFix", g[0] - t0,
                    lambda ns, g=g: navsatfix(ns, 0, g[1], g[2], g[3], [0.0] * 9, 0)))
        course = math.radians(g[5])
        out.append(("/ublox/fix_velocity", "geometry_msgs/msg/TwistWithCovarianceStamped", g[0] - t0,
                    lambda ns, g=g, c=course: velocity(ns, g[4] * math.sin(c), g[4] * math.cos(c))))
    for i in gyro:
        if i[0] <= end:
            out.append(("/phone/imu", "sensor_msgs/msg/Imu", i[0] - t0, lambda ns, i=i: imu(ns, *i[1:])))
    for w in wheels:
        if w[0] <= end:
            out.append(("/wheels/odom", "nav_msgs/msg/Odometry", w[0] - t0,
                        lambda ns, w=w: odometry(ns, (w[1] + w[2]) / 2, (w[2] - w[1]) / 1.57)))
    return out


def main():
    vehicle, data, fmt, out, start = sys.argv[1], Path(sys.argv[2]), sys.argv[3], Path(sys.argv[4]), int(sys.argv[5])
    messages = husky(data) if vehicle == "husky" else comma(data)
    if len(sys.argv) > 6:
        keep = sys.argv[6].split(",")
        messages = [m for m in messages if m[0] in keep]
    messages.sort(key=lambda m: m[2])
    if ROS1:
        from rosbags.rosbag1 import Writer
        writer = Writer(out)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer
        writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
    with writer:
        connections = {}
        for topic, msgtype, s, build in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=store)
            ns = start + round(s * 1e9)
            msg = build(ns)
            raw = store.serialize_ros1(msg, msgtype) if ROS1 else store.serialize_cdr(msg, msgtype)
            writer.write(connections[topic], ns, raw)


main()
