//! The status assembly: one snapshot of the vehicle at a tick, put together from its parts
//! (the localisation, the drive train, the task executive, the envelope, the battery and
//! the host), so every dialect reports the same state.

use std::time::Duration;

use super::chassis::Chassis;
use super::envelope::Envelope;
use super::executive::Executive;
use super::localisation::Localisation;
use super::status::{BatteryStatus, HostUsage, Pose2D, PoseReport, VehicleStatus};
use crate::devices::bms::{BmsReading, is_stale};
use crate::time::Timestamp;

/// The parts a status is read from, borrowed for one tick.
pub(super) struct Parts<'a> {
    /// Where the vehicle is (mutable: the status holds the last fresh heading).
    pub place: &'a mut Localisation,
    /// The drive train, when the vehicle has drives.
    pub chassis: Option<&'a Chassis>,
    /// The motion and the mission.
    pub executive: &'a Executive,
    /// The zones and the gate (mutable: their outlines are cached per placement).
    pub envelope: Option<&'a mut Envelope>,
    /// The last BMS reading.
    pub bms: Option<BmsReading>,
    /// A BMS reading older than this is stale; `None` without a BMS.
    pub bms_stale_after: Option<Duration>,
    /// The host's load, once sampled.
    pub host: Option<HostUsage>,
}

/// The status at `t` (without the corrections, which their own tick reports).
pub(super) fn status(t: Timestamp, parts: Parts<'_>) -> VehicleStatus {
    let Parts {
        place,
        chassis,
        executive,
        envelope,
        bms,
        bms_stale_after,
        host,
    } = parts;
    let report = place.pose_report(t);
    let pose = published_pose(&report);
    let PoseReport {
        odom,
        map,
        frames,
        localization,
    } = report;
    VehicleStatus {
        time: t,
        imu_ok: place.imu_ok(t),
        chassis: chassis.map(|c| c.status(t)),
        battery: battery(bms, bms_stale_after, t),
        gnss: place.gnss_status(t),
        pose,
        pose_covariance: map.map(|(_, covariance)| covariance),
        placement: place.localizer().map_placement(),
        odom,
        frames,
        localization,
        navigation: executive.navigation(),
        plan: executive.plan().cloned(),
        obstacle_stop: false,
        host,
        mode: chassis.map(Chassis::mode),
        corrections: None,
        mqtt_links: Vec::new(),
        envelope: envelope.map(|e| e.status(place.localizer(), chassis, t)),
    }
}

/// The battery as reported: the last reading (zero before the first) and whether it is stale
/// at `t`; `None` without a BMS.
fn battery(
    reading: Option<BmsReading>,
    stale_after: Option<Duration>,
    t: Timestamp,
) -> Option<BatteryStatus> {
    stale_after.map(|stale_after| {
        let reading = reading.unwrap_or_default();
        BatteryStatus {
            stale: is_stale(&reading, t, stale_after),
            reading,
        }
    })
}

/// The published pose: the map pose once GNSS (or INIT_POSITION) has placed the vehicle;
/// before that the odom frame's, which LOCATE_UNINIT marks; zero without either.
fn published_pose(report: &PoseReport) -> Pose2D {
    match (report.map, report.odom) {
        (Some((pose, _)), _) => pose,
        (None, Some(o)) => Pose2D {
            x: o.x,
            y: o.y,
            yaw: o.yaw,
        },
        (None, None) => Pose2D::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fusion::odometry::OdomPose;
    use crate::vehicle::status::{Localization, PoseCovariance};

    fn at(ms: u64) -> Timestamp {
        Timestamp::from_micros(ms * 1_000)
    }

    fn odom(x: f64) -> OdomPose {
        OdomPose {
            x,
            y: 2.0,
            yaw: 0.5,
            ..OdomPose::default()
        }
    }

    #[test]
    fn the_pose_is_the_map_pose_once_placed_else_the_odom_pose_else_zero() {
        let map = Pose2D {
            x: 10.0,
            y: 20.0,
            yaw: 1.0,
        };
        let mut report = PoseReport {
            odom: Some(odom(1.0)),
            map: Some((map, PoseCovariance::default())),
            frames: None,
            localization: Localization::Good,
        };
        assert_eq!(published_pose(&report), map);
        report.map = None;
        assert_eq!(
            published_pose(&report),
            Pose2D {
                x: 1.0,
                y: 2.0,
                yaw: 0.5
            }
        );
        report.odom = None;
        assert_eq!(published_pose(&report), Pose2D::default());
    }

    #[test]
    fn a_battery_is_reported_only_with_a_bms_and_is_stale_until_a_fresh_reading() {
        assert_eq!(battery(None, None, at(0)), None);
        let stale_after = Some(Duration::from_secs(5));
        let before_any = battery(None, stale_after, at(1_000)).expect("a BMS is configured");
        assert!(before_any.stale, "no reading yet is no charge level");
        let reading = BmsReading {
            rx: Some(at(1_000)),
            ..BmsReading::default()
        };
        assert!(
            !battery(Some(reading), stale_after, at(6_000))
                .unwrap()
                .stale
        );
        assert!(
            battery(Some(reading), stale_after, at(6_001))
                .unwrap()
                .stale
        );
    }
}
