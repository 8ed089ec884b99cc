//! The messages `chassisd import` reads from a bag, decoded from ROS1's serialisation or
//! ROS 2's CDR into plain samples: a receiver's fix (sensor_msgs/NavSatFix), its velocity
//! (geometry_msgs/TwistWithCovarianceStamped or TwistStamped, east and north), an IMU's rates
//! (sensor_msgs/Imu) and the wheels' odometry (nav_msgs/Odometry).
//!
//! The layouts are the message definitions' fields in order; ROS1's header has a `seq` and an
//! unsigned `sec`, ROS 2's neither.

use serde::Deserialize;

use super::BagKind;

/// A receiver's fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixSample {
    /// The header's stamp, ns since 1970.
    pub t_ns: u64,
    /// NavSatStatus: -1 no fix, 0 fix, 1 SBAS, 2 ground-based augmentation (RTK).
    pub status: i8,
    /// Latitude, longitude (degrees), altitude above the ellipsoid (m).
    pub position: (f64, f64, f64),
    /// The position's covariance (east, north, up; m², row-major).
    pub covariance: [f64; 9],
    /// Its type: 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub covariance_type: u8,
}

/// The receiver's velocity over ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocitySample {
    /// The header's stamp, ns.
    pub t_ns: u64,
    /// East and north, m/s.
    pub east_north: (f64, f64),
}

/// An IMU's angular rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuSample {
    /// The header's stamp, ns.
    pub t_ns: u64,
    /// The rate about the sensor's x, y, z, rad/s.
    pub rate: [f64; 3],
}

/// The wheels' odometry: forward speed and yaw rate in the child frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdomSample {
    /// The header's stamp, ns.
    pub t_ns: u64,
    /// Forward speed, m/s.
    pub vx: f64,
    /// Yaw rate, rad/s.
    pub wz: f64,
}

/// Why a message did not decode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct DecodeError(String);

#[derive(Deserialize)]
struct Ros1Header {
    _seq: u32,
    sec: u32,
    nsec: u32,
    _frame_id: String,
}

#[derive(Deserialize)]
struct Ros2Header {
    sec: i32,
    nanosec: u32,
    _frame_id: String,
}

/// A header's stamp, ns since 1970 (a stamp before 1970 reads 0).
trait Stamp {
    fn ns(&self) -> u64;
}

impl Stamp for Ros1Header {
    fn ns(&self) -> u64 {
        u64::from(self.sec) * 1_000_000_000 + u64::from(self.nsec)
    }
}

impl Stamp for Ros2Header {
    fn ns(&self) -> u64 {
        u64::try_from(self.sec).unwrap_or(0) * 1_000_000_000 + u64::from(self.nanosec)
    }
}

#[derive(Deserialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Deserialize)]
struct Quaternion {
    _x: f64,
    _y: f64,
    _z: f64,
    _w: f64,
}

/// A 6×6 covariance: serde reads fixed arrays up to 32, so two halves in a row (both
/// serialisations write a fixed array's elements one after another).
#[derive(Deserialize)]
struct Covariance36 {
    _first: [f64; 18],
    _second: [f64; 18],
}

#[derive(Deserialize)]
struct NavSatStatus {
    status: i8,
    _service: u16,
}

#[derive(Deserialize)]
struct NavSatFix<H> {
    header: H,
    status: NavSatStatus,
    latitude: f64,
    longitude: f64,
    altitude: f64,
    position_covariance: [f64; 9],
    position_covariance_type: u8,
}

#[derive(Deserialize)]
struct Imu<H> {
    header: H,
    _orientation: Quaternion,
    _orientation_covariance: [f64; 9],
    angular_velocity: Vector3,
    _angular_velocity_covariance: [f64; 9],
    _linear_acceleration: Vector3,
    _linear_acceleration_covariance: [f64; 9],
}

#[derive(Deserialize)]
struct Pose {
    _position: Vector3,
    _orientation: Quaternion,
}

#[derive(Deserialize)]
struct Twist {
    linear: Vector3,
    angular: Vector3,
}

#[derive(Deserialize)]
struct Odometry<H> {
    header: H,
    _child_frame_id: String,
    _pose: Pose,
    _pose_covariance: Covariance36,
    twist: Twist,
    _twist_covariance: Covariance36,
}

#[derive(Deserialize)]
struct TwistWithCovarianceStamped<H> {
    header: H,
    twist: Twist,
    _covariance: Covariance36,
}

#[derive(Deserialize)]
struct TwistStamped<H> {
    header: H,
    twist: Twist,
}

/// Decodes `bytes` as a `T<header>` of the bag's serialisation.
fn decode<T>(kind: BagKind, bytes: &[u8]) -> Result<T, DecodeError>
where
    T: for<'de> Deserialize<'de>,
{
    let failed = |e: &dyn std::fmt::Display| DecodeError(e.to_string());
    match kind {
        BagKind::Ros1 => {
            let len = u32::try_from(bytes.len()).map_err(|e| failed(&e))?;
            roslibrust_serde_rosmsg::from_reader_known_length(std::io::Cursor::new(bytes), len)
                .map_err(|e| failed(&e))
        }
        BagKind::Ros2 => {
            // CDR's encapsulation header: two bytes of kind (0x0001 little-endian), two of
            // options.
            let (head, body) = bytes
                .split_at_checked(4)
                .ok_or_else(|| DecodeError("shorter than CDR's header".into()))?;
            match head[1] {
                0x01 => cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body)
                    .map(|(v, _)| v)
                    .map_err(|e| failed(&e)),
                0x00 => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body)
                    .map(|(v, _)| v)
                    .map_err(|e| failed(&e)),
                other => Err(DecodeError(format!(
                    "CDR representation {other:#04x} is not plain CDR"
                ))),
            }
        }
    }
}

/// Decodes with the header of `kind`, then maps the message.
macro_rules! by_kind {
    ($kind:expr, $bytes:expr, $ty:ident, |$m:ident| $body:expr) => {
        match $kind {
            BagKind::Ros1 => decode::<$ty<Ros1Header>>($kind, $bytes).map(|$m| $body),
            BagKind::Ros2 => decode::<$ty<Ros2Header>>($kind, $bytes).map(|$m| $body),
        }
    };
}

/// A sensor_msgs/NavSatFix.
pub fn fix(kind: BagKind, bytes: &[u8]) -> Result<FixSample, DecodeError> {
    by_kind!(kind, bytes, NavSatFix, |m| FixSample {
        t_ns: m.header.ns(),
        status: m.status.status,
        position: (m.latitude, m.longitude, m.altitude),
        covariance: m.position_covariance,
        covariance_type: m.position_covariance_type,
    })
}

/// A sensor_msgs/Imu.
pub fn imu(kind: BagKind, bytes: &[u8]) -> Result<ImuSample, DecodeError> {
    by_kind!(kind, bytes, Imu, |m| ImuSample {
        t_ns: m.header.ns(),
        rate: [
            m.angular_velocity.x,
            m.angular_velocity.y,
            m.angular_velocity.z
        ],
    })
}

/// A nav_msgs/Odometry.
pub fn odometry(kind: BagKind, bytes: &[u8]) -> Result<OdomSample, DecodeError> {
    by_kind!(kind, bytes, Odometry, |m| OdomSample {
        t_ns: m.header.ns(),
        vx: m.twist.linear.x,
        wz: m.twist.angular.z,
    })
}

/// A geometry_msgs/TwistWithCovarianceStamped (as nmea_navsat_driver's `vel`): x east, y
/// north.
pub fn velocity_with_covariance(
    kind: BagKind,
    bytes: &[u8],
) -> Result<VelocitySample, DecodeError> {
    by_kind!(kind, bytes, TwistWithCovarianceStamped, |m| {
        VelocitySample {
            t_ns: m.header.ns(),
            east_north: (m.twist.linear.x, m.twist.linear.y),
        }
    })
}

/// A geometry_msgs/TwistStamped: x east, y north.
pub fn velocity(kind: BagKind, bytes: &[u8]) -> Result<VelocitySample, DecodeError> {
    by_kind!(kind, bytes, TwistStamped, |m| VelocitySample {
        t_ns: m.header.ns(),
        east_north: (m.twist.linear.x, m.twist.linear.y),
    })
}
