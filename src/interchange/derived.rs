//! What chassisd made of the inputs, as MCAP messages in Foxglove's well-known schemas
//! where one fits (so its map, 3D and log panels take them as they are) and as JSON with a
//! schema of its own otherwise.
//!
//! | topic | schema | from |
//! |---|---|---|
//! | `/gnss/fix` | foxglove.LocationFix | each new position report of the receiver |
//! | `/fused/fix` | foxglove.LocationFix | the map pose at each status tick, once placed |
//! | `/fused/pose` | foxglove.PoseInFrame (`map`) | the map pose at each control tick |
//! | `/tf` | foxglove.FrameTransforms | map→odom→base_link at each control tick |
//! | `/zones` | foxglove.GeoJSON | the zones at the start and after each edit |
//! | `/plan` | foxglove.PosesInFrame (`map`) | the path under way, when it changes |
//! | `/events` | foxglove.Log | the engine's events |
//! | `/status/base_status` | chassisd.BaseStatus | each status tick (10 Hz) |
//! | `/status/battery` | sensor_msgs/msg/BatteryState | every tenth status, with a BMS |
//! | `/status/diagnostics` | diagnostic_msgs/msg/DiagnosticArray | every tenth status |
//! | `/commands/results` | chassisd.CommandResult | each answer to a command |
//! | `/mqtt/published` | chassisd.MqttPublish | each message for the MQTT broker |

use serde_json::{Value, json};

use super::raw::{Message, time_json};
use super::schemas;
use crate::api::ros1::{BASE_FRAME, MAP_FRAME, ODOM_FRAME, yaw_quaternion};
use crate::api::ros2::messages::{GNSS_FRAME, position_covariance};
use crate::api::rosbridge::messages::{battery_state, diagnostics};
use crate::api::rtk::BaseStatus;
use crate::control::MotionId;
use crate::devices::gnss::GnssFix;
use crate::engine::EngineOutput;
use crate::time::Timestamp;
use crate::vehicle::{Event, Pose2D, PoseReport, VehicleStatus};

/// The battery and the diagnostics go out every this many statuses (1 Hz).
const SLOW_EVERY: u64 = 10;

/// foxglove.Log's levels.
const LOG_INFO: u8 = 2;
const LOG_WARNING: u8 = 3;

/// Turns engine outputs into messages; remembers what only goes out when it changes.
#[derive(Debug, Default)]
pub struct DerivedChannels {
    /// Statuses seen.
    statuses: u64,
    /// The motion whose plan `/plan` last carried (`Some(None)`: no motion).
    plan: Option<Option<MotionId>>,
    /// The receiver's last position report's time, sent on `/gnss/fix`.
    last_fix: Option<Timestamp>,
}

impl DerivedChannels {
    /// The messages of `output` (at `t`, the engine's time of the batch it came in), appended
    /// to `out` with the time each is logged at.
    pub fn messages(
        &mut self,
        output: &EngineOutput,
        t: Timestamp,
        out: &mut Vec<(Timestamp, Message)>,
    ) {
        match output {
            EngineOutput::Status(status) => self.status(status, out),
            EngineOutput::Poses(t, report) => poses(*t, report, out),
            EngineOutput::Fix(_, fix) => {
                out.extend(self.fix(fix));
            }
            EngineOutput::Event(event) => out.push((t, log(t, event))),
            EngineOutput::ZonesChanged(geojson) => out.push((t, zones(geojson))),
            EngineOutput::CommandResult {
                source,
                topic,
                request,
                result,
                data,
            } => out.push((
                t,
                Message::new(
                    "/commands/results",
                    schemas::COMMAND_RESULT,
                    &without_nulls(json!({
                        "timestamp": time_json(t),
                        "source": source,
                        "topic": topic,
                        "request": request,
                        "accepted": result.is_ok(),
                        "error": result.as_ref().err(),
                        "data": data.as_ref().map(Value::to_string),
                    })),
                ),
            )),
            EngineOutput::Publish(p) => out.push((
                t,
                Message::new(
                    "/mqtt/published",
                    schemas::MQTT_PUBLISH,
                    &json!({
                        "timestamp": time_json(t),
                        "topic": p.topic,
                        "qos": p.qos as u8,
                        "retain": p.retain,
                        "payload": String::from_utf8_lossy(&p.payload),
                    }),
                ),
            )),
            // Regenerated transmissions are the recorded ones (the raw channels carry
            // those); the rest repeat what the events and the statuses say.
            EngineOutput::SerialTx { .. }
            | EngineOutput::CanTx { .. }
            | EngineOutput::MotionEnded(_)
            | EngineOutput::Imu(_)
            | EngineOutput::Measured(_)
            | EngineOutput::Mission { .. } => {}
        }
    }

    fn status(&mut self, status: &VehicleStatus, out: &mut Vec<(Timestamp, Message)>) {
        let t = status.time;
        let base = BaseStatus::from_status(status);
        out.push((
            t,
            Message::new(
                "/status/base_status",
                schemas::BASE_STATUS,
                &serde_json::to_value(&base).unwrap_or(Value::Null),
            ),
        ));
        if let Some(m) = fused_fix(status) {
            out.push((t, m));
        }
        if self.statuses.is_multiple_of(SLOW_EVERY) {
            if let Some(battery) = battery_state(status) {
                out.push((
                    t,
                    Message::new(
                        "/status/battery",
                        schemas::BATTERY_STATE,
                        &without_nulls(battery),
                    ),
                ));
            }
            out.push((
                t,
                Message::new(
                    "/status/diagnostics",
                    schemas::DIAGNOSTIC_ARRAY,
                    &diagnostics(status),
                ),
            ));
        }
        self.statuses += 1;
        let plan = status.plan.as_ref().map(|p| p.id);
        if self.plan != Some(plan) {
            self.plan = Some(plan);
            let points = status.plan.as_ref().map_or(&[][..], |p| &p.points[..]);
            out.push((t, plan_message(t, points)));
        }
    }

    /// `/gnss/fix` when the receiver's position report is valid and new (a sentence that
    /// only adds to the epoch, a GST or a VTG, makes none); a lost fix makes none either
    /// (LocationFix has no "no fix"; the base_status shows it).
    fn fix(&mut self, fix: &GnssFix) -> Option<(Timestamp, Message)> {
        let position = fix.position.filter(|_| fix.quality.is_valid())?;
        if self.last_fix == Some(position.rx) {
            return None;
        }
        self.last_fix = Some(position.rx);
        let (covariance, kind) = position_covariance(fix, position.rx);
        let p = position.value;
        Some((
            position.rx,
            location_fix(
                "/gnss/fix",
                position.rx,
                GNSS_FRAME,
                (
                    p.latitude_deg,
                    p.longitude_deg,
                    p.height_above_ellipsoid_m(),
                ),
                covariance,
                kind,
            ),
        ))
    }
}

/// A LocationFix.
fn location_fix(
    topic: &str,
    t: Timestamp,
    frame: &str,
    (lat, lon, h): (f64, f64, f64),
    covariance: [f64; 9],
    kind: u8,
) -> Message {
    Message::new(
        topic,
        schemas::LOCATION_FIX,
        &json!({
            "timestamp": time_json(t),
            "frame_id": frame,
            "latitude": lat,
            "longitude": lon,
            "altitude": h,
            "position_covariance": covariance,
            "position_covariance_type": kind,
        }),
    )
}

/// `/fused/fix`: the map pose on the globe with its covariance turned into east and north
/// (LocationFix's "diagonal known" is not claimed: the filter's covariance has a cross term,
/// so it is "known"); height is the map plane's.
fn fused_fix(status: &VehicleStatus) -> Option<Message> {
    let (placement, c) = (status.placement?, status.pose_covariance?);
    let (lat, lon) = placement.geodetic(status.pose.x, status.pose.y);
    let (s, co) = placement.rotation().sin_cos();
    // R Σ Rᵀ for the map frame's rotation from east.
    let ee = co * co * c.xx - 2.0 * s * co * c.xy + s * s * c.yy;
    let nn = s * s * c.xx + 2.0 * s * co * c.xy + co * co * c.yy;
    let en = s * co * (c.xx - c.yy) + (co * co - s * s) * c.xy;
    const COVARIANCE_KNOWN: u8 = 3;
    Some(location_fix(
        "/fused/fix",
        status.time,
        BASE_FRAME,
        (lat, lon, placement.height_m()),
        [ee, en, 0.0, en, nn, 0.0, 0.0, 0.0, 0.0],
        COVARIANCE_KNOWN,
    ))
}

/// A planar pose as Foxglove's Pose.
fn pose(p: &Pose2D) -> Value {
    let [x, y, z, w] = yaw_quaternion(p.yaw);
    json!({
        "position": {"x": p.x, "y": p.y, "z": 0.0},
        "orientation": {"x": x, "y": y, "z": z, "w": w},
    })
}

/// `/fused/pose` and `/tf` of one control tick: map→odom→base_link once both frames exist.
fn poses(t: Timestamp, report: &PoseReport, out: &mut Vec<(Timestamp, Message)>) {
    if let Some((p, _)) = &report.map {
        out.push((
            t,
            Message::new(
                "/fused/pose",
                schemas::POSE_IN_FRAME,
                &json!({"timestamp": time_json(t), "frame_id": MAP_FRAME, "pose": pose(p)}),
            ),
        ));
    }
    let transforms = match (&report.frames, &report.map) {
        (Some(frames), _) => vec![
            transform(t, MAP_FRAME, ODOM_FRAME, &frames.map_to_odom),
            transform(t, ODOM_FRAME, BASE_FRAME, &frames.odom_to_base),
        ],
        // No odom frame (a vehicle without drives): the map pose is map→base_link itself.
        (None, Some((p, _))) => vec![transform(t, MAP_FRAME, BASE_FRAME, p)],
        (None, None) => return,
    };
    out.push((
        t,
        Message::new(
            "/tf",
            schemas::FRAME_TRANSFORMS,
            &json!({ "transforms": transforms }),
        ),
    ));
}

/// One FrameTransform: `child` at `p` in `parent`.
fn transform(t: Timestamp, parent: &str, child: &str, p: &Pose2D) -> Value {
    let [x, y, z, w] = yaw_quaternion(p.yaw);
    json!({
        "timestamp": time_json(t),
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": {"x": p.x, "y": p.y, "z": 0.0},
        "rotation": {"x": x, "y": y, "z": z, "w": w},
    })
}

/// `/plan`: the points of the motion under way (none: an empty path), each facing the next.
fn plan_message(t: Timestamp, points: &[(f64, f64)]) -> Message {
    let poses: Vec<Value> = points
        .iter()
        .enumerate()
        .map(|(i, &(x, y))| {
            let (from, to) = match (i.checked_sub(1).map(|j| points[j]), points.get(i + 1)) {
                (_, Some(&next)) => ((x, y), next),
                (Some(prev), None) => (prev, (x, y)),
                (None, None) => ((x, y), (x + 1.0, y)),
            };
            pose(&Pose2D {
                x,
                y,
                yaw: (to.1 - from.1).atan2(to.0 - from.0),
            })
        })
        .collect();
    Message::new(
        "/plan",
        schemas::POSES_IN_FRAME,
        &json!({"timestamp": time_json(t), "frame_id": MAP_FRAME, "poses": poses}),
    )
}

/// `/events`: an event as a log line; stops, faults and a closing gate are warnings.
fn log(t: Timestamp, event: &Event) -> Message {
    let (name, level) = match event {
        Event::SafetyStop(Some(_)) => ("safety", LOG_WARNING),
        Event::SafetyStop(None) => ("safety", LOG_INFO),
        Event::DriveFault { fault: Some(_), .. } => ("drives", LOG_WARNING),
        Event::DriveFault { .. } | Event::DriveRunning(_) => ("drives", LOG_INFO),
        Event::GateClosed(_) => ("gate", LOG_WARNING),
        Event::GateOpened => ("gate", LOG_INFO),
        Event::Localisation(_) => ("localisation", LOG_INFO),
        Event::Corrections(_) => ("corrections", LOG_INFO),
        Event::Motion(_) | Event::MotionEnded(_) => ("motion", LOG_INFO),
        Event::Mission(_) => ("mission", LOG_INFO),
        Event::Zone(_) | Event::ZoneEdited { .. } => ("zones", LOG_INFO),
        Event::Cutter { .. } => ("cutter", LOG_INFO),
        Event::Receiver(_) => ("receiver", LOG_INFO),
    };
    Message::new(
        "/events",
        schemas::LOG,
        &json!({
            "timestamp": time_json(t),
            "level": level,
            "message": event.to_string(),
            "name": format!("chassisd.{name}"),
            "file": "",
            "line": 0,
        }),
    )
}

/// `value` with its top-level `null`s left out: Foxglove's schemas have no null, and
/// ROS 2's messages say "not known" by NaN, which JSON cannot carry.
fn without_nulls(value: Value) -> Value {
    match value {
        Value::Object(map) => {
            Value::Object(map.into_iter().filter(|(_, v)| !v.is_null()).collect())
        }
        other => other,
    }
}

/// `/zones`: the zones (GeoJSON, WGS84), at the start and after each edit.
pub fn zones(geojson: &str) -> Message {
    Message::new("/zones", schemas::GEOJSON, &json!({"geojson": geojson}))
}
