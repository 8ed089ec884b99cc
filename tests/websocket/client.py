"""A rosbridge client (roslibpy, from PyPI) for tests/suite/websocket.rs.

    client.py PORT CHECK [ARGS...]

Each check talks to `chassisd sim --websocket 127.0.0.1:PORT` as an integrator's client
would, and prints one JSON object with what it saw; the Rust test judges it.
"""

import json
import math
import socket
import sys
import threading
import time

import roslibpy


def connect(port, token=None):
    ros = roslibpy.Ros(host="127.0.0.1", port=port)
    if token:
        # roslibpy sends `auth` when the connection is ready: it must be asked first.
        ros.authenticate(token, "", "", "", 0, "admin", 0)
    statuses = []

    # roslibpy has no handler for rosbridge's `status` operation: the test adds one.
    def on_status(message):
        statuses.append(dict(message))

    ros.factory.on_ready(lambda proto: proto._message_handlers.__setitem__("status", on_status))
    ros.run(timeout=10)
    return ros, statuses


def rates(ros, _statuses, seconds="4"):
    seconds = float(seconds)
    seen = {"/pose": [], "/odom": [], "/battery_state": [], "/diagnostics": [], "/tf": []}
    subs = []
    for topic, kind in [("/pose", "geometry_msgs/PoseWithCovarianceStamped"), ("/odom", "nav_msgs/Odometry"),
                        ("/tf", "tf2_msgs/TFMessage"),
                        ("/battery_state", "sensor_msgs/BatteryState"), ("/diagnostics", "diagnostic_msgs/DiagnosticArray")]:
        t = roslibpy.Topic(ros, topic, kind)
        t.subscribe(lambda m, topic=topic: seen[topic].append((time.monotonic(), m)))
        subs.append(t)
    time.sleep(1.0)
    for v in seen.values():
        v.clear()
    time.sleep(seconds)
    for t in subs:
        t.unsubscribe()
    pose, odom = seen["/pose"][-1][1], seen["/odom"][-1][1]
    battery = seen["/battery_state"][-1][1] if seen["/battery_state"] else {}
    diagnostics = seen["/diagnostics"][-1][1] if seen["/diagnostics"] else {"status": []}
    # The frame tree: map→odom composed with odom→base_link is the /pose of the same stamp.
    poses = {json.dumps(m["header"]["stamp"], sort_keys=True): m["pose"]["pose"] for _, m in seen["/pose"]}
    tf_frames, tf_vs_pose = set(), []
    for _, m in seen["/tf"]:
        by_child = {}
        for tr in m["transforms"]:
            tf_frames.add(tr["header"]["frame_id"] + ">" + tr["child_frame_id"])
            by_child[tr["child_frame_id"]] = tr
        same = poses.get(json.dumps(m["transforms"][0]["header"]["stamp"], sort_keys=True))
        if same is None or "odom" not in by_child or "base_link" not in by_child:
            continue
        c, o = by_child["odom"]["transform"], by_child["base_link"]["transform"]
        cyaw = yaw_of(c["rotation"])
        ox, oy = o["translation"]["x"], o["translation"]["y"]
        x = c["translation"]["x"] + math.cos(cyaw) * ox - math.sin(cyaw) * oy
        y = c["translation"]["y"] + math.sin(cyaw) * ox + math.cos(cyaw) * oy
        yaw = cyaw + yaw_of(o["rotation"])
        dyaw = (yaw - yaw_of(same["orientation"]) + math.pi) % (2 * math.pi) - math.pi
        tf_vs_pose.append(max(math.hypot(x - same["position"]["x"], y - same["position"]["y"]), abs(dyaw)))
    return {
        "tf_hz": len(seen["/tf"]) / seconds,
        "tf_frames": sorted(tf_frames),
        "tf_compared": len(tf_vs_pose),
        "tf_vs_pose": max(tf_vs_pose) if tf_vs_pose else None,
        "battery_hz": len(seen["/battery_state"]) / seconds,
        "voltage": battery.get("voltage"),
        "percentage": battery.get("percentage"),
        "diagnostics": [d["name"] for d in diagnostics["status"]],
        "pose_hz": len(seen["/pose"]) / seconds,
        "odom_hz": len(seen["/odom"]) / seconds,
        "pose_frame": pose["header"]["frame_id"],
        "pose_covariance": len(pose["pose"]["covariance"]),
        "odom_frame": odom["header"]["frame_id"],
        "odom_child": odom["child_frame_id"],
        "stamp": odom["header"]["stamp"],
    }


def latest(ros, topic, kind, wait=5.0):
    box = []
    t = roslibpy.Topic(ros, topic, kind)
    t.subscribe(lambda m: box.append(m))
    deadline = time.monotonic() + wait
    while not box and time.monotonic() < deadline:
        time.sleep(0.05)
    t.unsubscribe()
    return box[-1] if box else None


def echo(ros, _statuses, topic, kind):
    """The latest message of one topic, as a client subscribed to it sees it."""
    return {"message": latest(ros, topic, kind)}


def yaw_of(q):
    return 2.0 * math.atan2(q["z"], q["w"])


def goal(ros, _statuses, x, y, yaw_deg):
    x, y, yaw = float(x), float(y), math.radians(float(yaw_deg))
    plans = []
    plan = roslibpy.Topic(ros, "/plan", "nav_msgs/Path")
    plan.subscribe(lambda m: plans.append([(p["pose"]["position"]["x"], p["pose"]["position"]["y"]) for p in m["poses"]]))
    pub = roslibpy.Topic(ros, "/goal_pose", "geometry_msgs/PoseStamped")
    pub.advertise()
    time.sleep(0.5)
    pub.publish(roslibpy.Message({
        "header": {"frame_id": "map", "stamp": {"sec": 0, "nanosec": 0}},
        "pose": {"position": {"x": x, "y": y, "z": 0.0},
                 "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}},
    }))
    deadline = time.monotonic() + 60
    pose = None
    while time.monotonic() < deadline:
        m = latest(ros, "/pose", "geometry_msgs/PoseWithCovarianceStamped")
        if m:
            p = m["pose"]["pose"]
            pose = {"x": p["position"]["x"], "y": p["position"]["y"], "yaw": yaw_of(p["orientation"])}
            odom = latest(ros, "/odom", "nav_msgs/Odometry")
            twist = odom["twist"]["twist"] if odom else None
            still = twist and abs(twist["linear"]["x"]) < 0.01 and abs(twist["angular"]["z"]) < 0.01
            if math.hypot(pose["x"] - x, pose["y"] - y) < 0.05 and still:
                break
        time.sleep(0.2)
    time.sleep(0.5)
    plan.unsubscribe()
    return {"pose": pose, "plans": plans}


def cmd_vel(ros, _statuses, speed="0.3", seconds="2"):
    speed, seconds = float(speed), float(seconds)
    twists = []
    odom = roslibpy.Topic(ros, "/odom", "nav_msgs/Odometry")
    odom.subscribe(lambda m: twists.append((time.monotonic(), m["twist"]["twist"]["linear"]["x"])))
    pub = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist")
    pub.advertise()
    time.sleep(0.5)
    start = time.monotonic()
    while time.monotonic() - start < seconds:
        pub.publish(roslibpy.Message({"linear": {"x": speed, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}))
        time.sleep(0.1)
    stopped = time.monotonic()
    time.sleep(2.0)
    odom.unsubscribe()
    during = [v for t, v in twists if start + 1.0 <= t <= stopped]
    after = [v for t, v in twists if t >= stopped + 1.5]
    return {"max_during": max(during, default=0.0), "after": after[-1] if after else None}


def envelope_values(m):
    return {v["key"]: v["value"] for v in m["values"]}


def zones_jog(ros, statuses, speed="0.5", seconds="12"):
    """/zones as a late subscriber gets it, and /safety_envelope through a jog."""
    zones = latest(ros, "/zones", "visualization_msgs/MarkerArray")
    envelopes = []
    env = roslibpy.Topic(ros, "/safety_envelope", "diagnostic_msgs/DiagnosticStatus")
    env.subscribe(lambda m: envelopes.append({"level": m["level"], "message": m["message"], **envelope_values(m)}))
    time.sleep(1.0)
    first = envelopes[-1] if envelopes else None
    jog = cmd_vel(ros, statuses, speed, seconds)
    env.unsubscribe()
    metres = lambda key: [float(e[key]) for e in envelopes if e[key] != "unknown"]
    return {
        "markers": [{"ns": m["ns"], "id": m["id"], "action": m["action"], "text": m.get("text", ""),
                     "frame": m["header"]["frame_id"], "points": m.get("points", [])} for m in zones["markers"]],
        "first": first,
        "last": envelopes[-1] if envelopes else None,
        "envelope_count": len(envelopes),
        "max_margin": max(metres("margin_m"), default=None),
        "min_clearance": min(metres("clearance_m"), default=None),
        "jog": jog,
    }


def refusals(ros, statuses):
    roslibpy.Topic(ros, "/map", "nav_msgs/OccupancyGrid").subscribe(lambda m: None)
    roslibpy.Topic(ros, "/scan", "sensor_msgs/LaserScan").subscribe(lambda m: None)
    bad = roslibpy.Topic(ros, "/goal_pose", "geometry_msgs/PoseStamped")
    bad.publish(roslibpy.Message({"header": {"frame_id": "odom"}, "pose": {"position": {"x": 1, "y": 1}}}))
    deadline = time.monotonic() + 5
    while len(statuses) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    topics = ros.get_topics()
    return {"statuses": [s.get("msg", "") for s in statuses], "levels": [s.get("level") for s in statuses], "topics": topics}


def auth(ros, statuses, token, port):
    """Nothing on a connection without the token; everything on one that presents it."""
    before, after = [], []
    roslibpy.Topic(ros, "/diagnostics", "diagnostic_msgs/DiagnosticArray").subscribe(before.append)
    time.sleep(2.5)
    authed, _ = connect(int(port), token)
    roslibpy.Topic(authed, "/diagnostics", "diagnostic_msgs/DiagnosticArray").subscribe(after.append)
    deadline = time.monotonic() + 5
    while not after and time.monotonic() < deadline:
        time.sleep(0.05)
    authed.close()
    return {
        "before": len(before),
        "refused": [s.get("msg", "") for s in statuses],
        "after": len(after),
        "statuses": [s.get("level", "") for s in after[-1]["status"]] if after else [],
    }


def raw_first_message(port, path, topic, wait=5.0):
    """Connects to PATH with a raw WebSocket handshake, subscribes to TOPIC and returns the
    first text message the server sends."""
    s = socket.create_connection(("127.0.0.1", port), timeout=wait)
    s.sendall(("GET %s HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n" % path).encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += s.recv(1)
    payload = json.dumps({"op": "subscribe", "topic": topic}).encode()
    mask = b"\x01\x02\x03\x04"
    s.sendall(bytes([0x81, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload)))

    def exactly(n):
        data = b""
        while len(data) < n:
            chunk = s.recv(n - len(data))
            if not chunk:
                raise EOFError
            data += chunk
        return data

    first, second = exactly(2)
    length = second & 0x7F
    if length == 126:
        length = int.from_bytes(exactly(2), "big")
    elif length == 127:
        length = int.from_bytes(exactly(8), "big")
    text = exactly(length).decode()
    s.close()
    return json.loads(text)


def url_token(_ros, _statuses, port, token):
    port = int(port)
    with_token = raw_first_message(port, "/?token=%s" % token, "/diagnostics")
    without = raw_first_message(port, "/", "/diagnostics")
    return {"with_token": with_token.get("op"), "without": without.get("op"), "without_msg": without.get("msg", "")}


def silent_client(port):
    """A client that subscribes to /odom with a long queue and never reads again."""
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    # A small window, set before connecting: the server's writes back up soon.
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    s.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
              b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
    head = b""
    while b"\r\n\r\n" not in head:
        head += s.recv(1)
    for topic in ["/odom", "/pose", "/diagnostics"]:
        payload = json.dumps({"op": "subscribe", "topic": topic, "queue_length": 100}).encode()
        mask = b"\x01\x02\x03\x04"
        frame = bytes([0x81, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        s.sendall(frame)
    return s


def slow(ros, _statuses, port, seconds="10"):
    seconds = float(seconds)
    silent = silent_client(int(port))
    times = []
    t = roslibpy.Topic(ros, "/pose", "geometry_msgs/PoseWithCovarianceStamped")
    t.subscribe(lambda m: times.append(time.monotonic()))
    time.sleep(seconds)
    t.unsubscribe()
    gaps = [b - a for a, b in zip(times, times[1:])]
    silent.close()
    return {"pose_hz": len(times) / seconds, "largest_gap_s": max(gaps, default=None)}


def main():
    port = int(sys.argv[1])
    check = sys.argv[2]
    args = sys.argv[3:]
    ros, statuses = connect(port)
    if check in ("slow", "url_token"):
        args = [str(port)] + args
    if check == "auth":
        args = args + [str(port)]
    result = globals()[check](ros, statuses, *args)
    print(json.dumps(result), flush=True)
    ros.close()
    ros.terminate()


if __name__ == "__main__":
    main()
