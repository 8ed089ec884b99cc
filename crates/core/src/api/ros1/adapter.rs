//! The ROS1 node's requests, typed: what each topic and service asks of the core, the form
//! the node records it in (its ROS name as the topic, `{"id": ID, "msg": MESSAGE}` with the
//! message's fields as JSON), and the adapter that hands it to the core and answers it.

use serde::{Deserialize, Serialize};

use super::queries::{
    self, Empty, GET_POSITION, NAVI_INFO, ROBOT_SSH, RobotSsh, SET_WIFI, SetWifi,
};
use super::{OWNER, SOURCE};
use crate::api::adapter::{self, Adapter, CoreAccess, Handled, Reply};
use crate::api::legacy;
use crate::api::requests::{self, Twist};
use crate::control::MotionTag;
use crate::time::Timestamp;
use crate::vehicle::Command;
use crate::vehicle::zones::{MapShape, ZoneEdit};
use crate::zones::ZoneKind;

/// `/cmd_vel`'s name.
pub const CMD_VEL: &str = "/cmd_vel";
/// `/navi_stop`'s name.
pub const NAVI_STOP: &str = "/navi_stop";
/// `/autocharge`'s name.
pub const AUTOCHARGE: &str = "/autocharge";
/// `/set_navi_cmd`'s name.
pub const SET_NAVI_CMD: &str = "/set_navi_cmd";
/// `/set_shape`'s name.
pub const SET_SHAPE: &str = "/set_shape";
/// `/set_region`'s name.
pub const SET_REGION: &str = "/set_region";
/// Characters of a `/robot_ssh` instruction kept in the recording (and the log).
const SHOWN_INSTRUCTION: usize = 200;
/// Characters of a `/set_wifi` network name kept in the recording; its password never is.
const SHOWN_WIFI_NAME: usize = 64;

/// A request of the node (also as the node's process hands it to chassisd's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Ros1Request {
    /// `/cmd_vel` (geometry_msgs/Twist): through the arbiter and the command watchdog like
    /// every velocity source; components a ground vehicle cannot follow are refused.
    CmdVel {
        /// m/s.
        linear: [f64; 3],
        /// rad/s.
        angular: [f64; 3],
    },
    /// `/navi_stop` 5: every move, goal, task or mission ends, without latching.
    NaviStop,
    /// `/autocharge` 1: a mission of one CHARGING step.
    Autocharge,
    /// `/set_navi_cmd` with the request's fields.
    SetNaviCmd {
        /// "1" forward, "2" back, "3" left, "4" right, "5" stop.
        cmd: String,
        /// cm or degrees.
        distance: i64,
    },
    /// `/set_shape` (map_msgs/SetShape): a virtual wall added (no `shapeId`) or removed.
    SetShape(ShapeRequest),
    /// `/set_region` (map_msgs/SetRegion): a special region added (no `shapeId`) or removed.
    SetRegion(RegionRequest),
    /// `/get_position` (map_msgs/GetPosition): where the vehicle is in the map frame.
    GetPosition,
    /// `/navi_info` (map_msgs/AboutRobot): what the build is.
    NaviInfo,
    /// `/robot_ssh` (map_msgs/RobotSsh): a shell command, always refused; the first
    /// [`SHOWN_INSTRUCTION`] characters are kept, to be seen in the recording.
    RobotSsh {
        /// The instruction, cut.
        instruction: String,
    },
    /// `/set_wifi` (map_msgs/SetWifi): a network to join, always refused; its name is kept
    /// (cut to [`SHOWN_WIFI_NAME`] characters), its password is not.
    SetWifi {
        /// The network's name, cut.
        wifi_name: String,
    },
}

/// geometry_msgs/Point as JSON.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// m.
    pub x: f64,
    /// m.
    pub y: f64,
    /// m (not used: zones are flat).
    pub z: f64,
}

/// map_msgs/SetShape's request as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeRequest {
    /// `lines` or `circle`.
    #[serde(rename = "type")]
    pub kind: String,
    /// The shape to remove; 0 (no id) adds one.
    #[serde(rename = "shapeId")]
    pub shape_id: i64,
    /// The points (map frame).
    pub points: Vec<Point>,
    /// A circle's radius, m.
    pub radius: f32,
    /// Lines joined last to first.
    pub closed: bool,
}

/// map_msgs/SetRegion's request as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionRequest {
    /// `lines` only.
    #[serde(rename = "type")]
    pub kind: String,
    /// The region to remove; 0 (no id) adds one.
    #[serde(rename = "shapeId")]
    pub shape_id: i64,
    /// The outline (map frame).
    pub points: Vec<Point>,
    /// The route across the region (kept by the navigation stack; chassisd plans none).
    pub points2: Vec<Point>,
    /// Waiting points at the route's start.
    #[serde(rename = "startPointWaits")]
    pub start_waits: Vec<Point>,
    /// Waiting points at the route's end.
    #[serde(rename = "endPointWaits")]
    pub end_waits: Vec<Point>,
    /// Not used by regions.
    pub radius: f32,
    /// Must be true: a region is a closed outline.
    pub closed: bool,
}

/// std_msgs/Int16 as JSON.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Int16 {
    data: i16,
}

/// map_msgs/SetNaviCmd's request as JSON.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct SetNaviCmd {
    cmd: String,
    distance: i64,
}

impl Ros1Request {
    /// `/navi_stop`: 5 stops every motion; any other value is refused.
    pub fn navi_stop(data: i16) -> Result<Self, String> {
        match data {
            5 => Ok(Self::NaviStop),
            _ => Err(format!("/navi_stop takes 5 (stop), not {data}")),
        }
    }

    /// `/autocharge`: 1 starts the charging action; any other value is refused.
    pub fn autocharge(data: i16) -> Result<Self, String> {
        match data {
            1 => Ok(Self::Autocharge),
            _ => Err(format!("/autocharge takes 1 (charge), not {data}")),
        }
    }

    /// `/robot_ssh` with `instruction`, cut to what is kept.
    pub fn robot_ssh(instruction: &str) -> Self {
        Self::RobotSsh {
            instruction: instruction.chars().take(SHOWN_INSTRUCTION).collect(),
        }
    }

    /// `/set_wifi` for the network `name`, cut to what is kept (the password is left out
    /// by the caller: it is never recorded).
    pub fn set_wifi(name: &str) -> Self {
        Self::SetWifi {
            wifi_name: name.chars().take(SHOWN_WIFI_NAME).collect(),
        }
    }

    /// The request with only what chassisd keeps of its free text: the node's process cuts
    /// it already, and chassisd does not rely on another process for what it records.
    pub fn kept(self) -> Self {
        match self {
            Self::RobotSsh { instruction } => Self::robot_ssh(&instruction),
            Self::SetWifi { wifi_name } => Self::set_wifi(&wifi_name),
            other => other,
        }
    }

    /// Its topic's or service's name.
    pub fn name(&self) -> &'static str {
        match self {
            Self::CmdVel { .. } => CMD_VEL,
            Self::NaviStop => NAVI_STOP,
            Self::Autocharge => AUTOCHARGE,
            Self::SetNaviCmd { .. } => SET_NAVI_CMD,
            Self::SetShape(_) => SET_SHAPE,
            Self::SetRegion(_) => SET_REGION,
            Self::GetPosition => GET_POSITION,
            Self::NaviInfo => NAVI_INFO,
            Self::RobotSsh { .. } => ROBOT_SSH,
            Self::SetWifi { .. } => SET_WIFI,
        }
    }

    /// Whether the node waits for its answer: every request but a velocity command (whose
    /// answer is only logged).
    pub fn awaits_answer(&self) -> bool {
        !matches!(self, Self::CmdVel { .. })
    }

    /// Whether, accepted, it starts a motion (whose start the node announces).
    pub fn starts_motion(&self) -> bool {
        match self {
            Self::Autocharge => true,
            // Command 5 is the stop; every other one taken is a move.
            Self::SetNaviCmd { cmd, .. } => cmd != "5",
            Self::CmdVel { .. }
            | Self::NaviStop
            | Self::SetShape(_)
            | Self::SetRegion(_)
            | Self::GetPosition
            | Self::NaviInfo
            | Self::RobotSsh { .. }
            | Self::SetWifi { .. } => false,
        }
    }

    /// Whether it edits the zones (answered on `/androidmsg_virtualmapstatus`).
    pub fn edits_zones(&self) -> bool {
        matches!(self, Self::SetShape(_) | Self::SetRegion(_))
    }

    /// Whether it is the charging action.
    pub fn is_charging(&self) -> bool {
        *self == Self::Autocharge
    }

    /// The record payload of the request, with `id` when its answer is awaited.
    pub fn encode(&self, id: Option<u64>) -> bytes::Bytes {
        match self {
            Self::CmdVel { linear, angular } => {
                adapter::encode_request(id, &Twist::new(*linear, *angular))
            }
            Self::NaviStop => adapter::encode_request(id, &Int16 { data: 5 }),
            Self::Autocharge => adapter::encode_request(id, &Int16 { data: 1 }),
            Self::SetNaviCmd { cmd, distance } => adapter::encode_request(
                id,
                &SetNaviCmd {
                    cmd: cmd.clone(),
                    distance: *distance,
                },
            ),
            Self::SetShape(m) => adapter::encode_request(id, m),
            Self::SetRegion(m) => adapter::encode_request(id, m),
            Self::GetPosition | Self::NaviInfo => adapter::encode_request(id, &Empty {}),
            Self::RobotSsh { instruction } => adapter::encode_request(
                id,
                &RobotSsh {
                    instruction: instruction.clone(),
                },
            ),
            Self::SetWifi { wifi_name } => adapter::encode_request(
                id,
                &SetWifi {
                    wifi_name: wifi_name.clone(),
                },
            ),
        }
    }
}

/// A recorded request's id and core command (missions and goals tagged as the node's).
pub fn decode(topic: &str, payload: &[u8]) -> (Option<u64>, Result<Command, String>) {
    if legacy::is_legacy(topic) {
        return (None, legacy::decode(topic, payload).map(tagged));
    }
    let (id, command) = match topic {
        CMD_VEL => {
            let (id, twist) = adapter::decode_request::<Twist>(topic, payload);
            (id, twist.and_then(|t| requests::velocity(&t)))
        }
        NAVI_STOP | AUTOCHARGE => {
            let (id, m) = adapter::decode_request::<Int16>(topic, payload);
            let command = m.and_then(|m| match topic {
                NAVI_STOP => Ros1Request::navi_stop(m.data).map(|_| Command::CancelMotion),
                _ => Ros1Request::autocharge(m.data).map(|_| requests::charge()),
            });
            (id, command)
        }
        SET_NAVI_CMD => {
            let (id, m) = adapter::decode_request::<SetNaviCmd>(topic, payload);
            let command = m.and_then(|m| {
                requests::navi_cmd(&serde_json::Value::String(m.cmd), Some(m.distance as f64))
            });
            (id, command)
        }
        SET_SHAPE => {
            let (id, m) = adapter::decode_request::<ShapeRequest>(topic, payload);
            (id, m.and_then(|m| shape_edit(&m)).map(Command::EditZones))
        }
        SET_REGION => {
            let (id, m) = adapter::decode_request::<RegionRequest>(topic, payload);
            (id, m.and_then(|m| region_edit(&m)).map(Command::EditZones))
        }
        _ => (None, Err(format!("unknown topic {topic:?}"))),
    };
    (id, command.map(tagged))
}

/// The zone a shape id names, when it names one (0 is no id: an addition).
fn removal(service: &str, shape_id: i64) -> Result<Option<ZoneEdit>, String> {
    match shape_id {
        0 => Ok(None),
        id => u32::try_from(id)
            .map(|id| Some(ZoneEdit::Remove(id)))
            .map_err(|_| format!("{service}: shapeId {id} names no zone (ids are 1 to 2^32 - 1)")),
    }
}

/// The points in the map frame, each a finite number.
fn plane(service: &str, points: &[Point]) -> Result<Vec<(f64, f64)>, String> {
    points
        .iter()
        .map(|p| {
            if p.x.is_finite() && p.y.is_finite() {
                Ok((p.x, p.y))
            } else {
                Err(format!("{service}: a point is not a finite number"))
            }
        })
        .collect()
}

/// `/set_shape`: a wall along `lines` (joined last to first when `closed`), or a keep-out
/// circle round the first point; with a `shapeId`, that zone's removal.
fn shape_edit(m: &ShapeRequest) -> Result<ZoneEdit, String> {
    if let Some(removal) = removal(SET_SHAPE, m.shape_id)? {
        return Ok(removal);
    }
    let mut points = plane(SET_SHAPE, &m.points)?;
    match m.kind.as_str() {
        "lines" => {
            if m.closed
                && let Some(&first) = points.first()
            {
                points.push(first);
            }
            Ok(ZoneEdit::Add {
                name: "virtual wall".into(),
                kind: ZoneKind::Wall,
                shape: MapShape::Line(points),
            })
        }
        "circle" => match points.first() {
            Some(&centre) => Ok(ZoneEdit::Add {
                name: "virtual circle".into(),
                kind: ZoneKind::KeepOut,
                shape: MapShape::Circle(centre, f64::from(m.radius)),
            }),
            None => Err(format!(
                "{SET_SHAPE}: a circle needs its centre as the first point"
            )),
        },
        other => Err(format!(
            "{SET_SHAPE}: type must be lines or circle, not {:?}",
            other.chars().take(40).collect::<String>()
        )),
    }
}

/// `/set_region`: a closed outline the vehicle keeps out of (the route across it is the
/// navigation stack's); with a `shapeId`, that zone's removal.
fn region_edit(m: &RegionRequest) -> Result<ZoneEdit, String> {
    if let Some(removal) = removal(SET_REGION, m.shape_id)? {
        return Ok(removal);
    }
    if m.kind != "lines" || !m.closed {
        return Err(format!(
            "{SET_REGION}: a region is type lines with closed true (the spec allows no other)"
        ));
    }
    Ok(ZoneEdit::Add {
        name: "special region".into(),
        kind: ZoneKind::KeepOut,
        shape: MapShape::Polygon(plane(SET_REGION, &m.points)?),
    })
}

/// The node's tag on a mission or goal it asked for, so it can tell that mission's end.
fn tagged(command: Command) -> Command {
    requests::tagged(
        command,
        MotionTag {
            owner: OWNER,
            id: 0,
        },
    )
}

/// The ROS1 node's adapter: commands go to the core, queries read it
/// ([`super::queries`]).
#[derive(Debug, Clone)]
pub struct Ros1Adapter {
    /// `/navi_info`'s answer.
    about: String,
}

impl Ros1Adapter {
    /// The adapter of the vehicle called `vehicle`.
    pub fn new(vehicle: &str) -> Self {
        Self {
            about: super::navi_info(vehicle),
        }
    }
}

impl Adapter for Ros1Adapter {
    fn source(&self) -> &'static str {
        SOURCE
    }

    fn on_request(
        &mut self,
        _t: Timestamp,
        topic: &str,
        payload: &[u8],
        core: &mut dyn CoreAccess,
        out: &mut Vec<Reply>,
    ) -> Handled {
        match queries::answer(topic, payload, &self.about, core) {
            Some(answer) => {
                let handled = if answer.result.is_ok() {
                    Handled::Answered
                } else {
                    Handled::Refused
                };
                out.push(Reply::Answer(answer));
                handled
            }
            None => {
                let (id, command) = decode(topic, payload);
                adapter::answer(topic, id, command, core, out)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::MoveKind;

    fn round_trip(
        request: &Ros1Request,
        id: Option<u64>,
    ) -> (Option<u64>, Result<Command, String>) {
        decode(request.name(), &request.encode(id))
    }

    #[test]
    fn requests_decode_to_the_core_commands_with_their_ids() {
        let twist = Ros1Request::CmdVel {
            linear: [0.3, 0.0, 0.0],
            angular: [0.0, 0.0, 0.2],
        };
        assert_eq!(
            round_trip(&twist, None),
            (None, Ok(Command::Velocity { vx: 0.3, wz: 0.2 }))
        );
        assert!(!twist.awaits_answer() && !twist.starts_motion());
        let forward = Ros1Request::SetNaviCmd {
            cmd: "1".into(),
            distance: 50,
        };
        assert_eq!(
            round_trip(&forward, Some(4)),
            (
                Some(4),
                Ok(Command::Move(MoveKind::Straight { distance_m: 0.5 }))
            )
        );
        assert!(forward.awaits_answer() && forward.starts_motion());
        let stop = Ros1Request::navi_stop(5).unwrap();
        assert_eq!(
            round_trip(&stop, Some(5)),
            (Some(5), Ok(Command::CancelMotion))
        );
        assert!(!stop.starts_motion());
        let charge = Ros1Request::autocharge(1).unwrap();
        assert!(charge.is_charging() && charge.starts_motion());
        assert!(matches!(
            round_trip(&charge, Some(6)),
            (
                Some(6),
                Ok(Command::Mission {
                    tag: Some(MotionTag { owner: OWNER, .. }),
                    ..
                })
            )
        ));
    }

    #[test]
    fn what_a_vehicle_cannot_do_is_refused_with_the_reason() {
        assert!(Ros1Request::navi_stop(4).unwrap_err().contains("takes 5"));
        assert!(Ros1Request::autocharge(0).unwrap_err().contains("takes 1"));
        let sideways = Ros1Request::CmdVel {
            linear: [0.3, 0.5, 0.0],
            angular: [0.0; 3],
        };
        assert!(round_trip(&sideways, None).1.is_err());
        let nine = Ros1Request::SetNaviCmd {
            cmd: "9".into(),
            distance: 10,
        };
        let (id, refused) = round_trip(&nine, Some(8));
        assert_eq!(id, Some(8));
        assert!(refused.unwrap_err().contains("cmd must be"));
        // A record is a claim: a stored /navi_stop of 4 is refused on replay too.
        let (_, forged) = decode(NAVI_STOP, br#"{"id":1,"msg":{"data":4}}"#);
        assert!(forged.unwrap_err().contains("takes 5"));
        assert!(
            decode("/elsewhere", b"{}")
                .1
                .unwrap_err()
                .contains("unknown topic")
        );
    }

    fn shape(kind: &str, shape_id: i64, points: &[(f64, f64)], closed: bool) -> Ros1Request {
        Ros1Request::SetShape(ShapeRequest {
            kind: kind.into(),
            shape_id,
            points: points
                .iter()
                .map(|&(x, y)| Point { x, y, z: 0.0 })
                .collect(),
            radius: 1.5,
            closed,
        })
    }

    #[test]
    fn set_shape_adds_walls_and_circles_and_removes_by_id() {
        let wall = shape("lines", 0, &[(0.0, 0.0), (2.0, 0.0), (2.0, 2.0)], true);
        assert!(wall.edits_zones() && wall.awaits_answer() && !wall.starts_motion());
        let (id, edit) = round_trip(&wall, Some(3));
        assert_eq!(id, Some(3));
        let Ok(Command::EditZones(ZoneEdit::Add {
            kind, shape: line, ..
        })) = edit
        else {
            panic!("{edit:?}");
        };
        assert_eq!(kind, ZoneKind::Wall);
        // Closed: joined back to its first point.
        assert_eq!(
            line,
            MapShape::Line(vec![(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 0.0)])
        );
        let (_, circle) = round_trip(&shape("circle", 0, &[(4.0, 1.0)], false), Some(4));
        assert!(matches!(
            circle,
            Ok(Command::EditZones(ZoneEdit::Add {
                kind: ZoneKind::KeepOut,
                shape: MapShape::Circle((4.0, 1.0), 1.5),
                ..
            }))
        ));
        let (_, removal) = round_trip(&shape("lines", 7, &[], false), Some(5));
        assert_eq!(removal, Ok(Command::EditZones(ZoneEdit::Remove(7))));
        let region = Ros1Request::SetRegion(RegionRequest {
            kind: "lines".into(),
            shape_id: 0,
            points: [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]
                .iter()
                .map(|&(x, y)| Point { x, y, z: 0.0 })
                .collect(),
            points2: Vec::new(),
            start_waits: Vec::new(),
            end_waits: Vec::new(),
            radius: 0.0,
            closed: true,
        });
        assert!(matches!(
            round_trip(&region, Some(6)).1,
            Ok(Command::EditZones(ZoneEdit::Add {
                kind: ZoneKind::KeepOut,
                shape: MapShape::Polygon(_),
                ..
            }))
        ));
    }

    #[test]
    fn bad_zone_edits_are_refused_with_the_reason() {
        for (request, says) in [
            (shape("square", 0, &[(0.0, 0.0)], false), "lines or circle"),
            (shape("circle", 0, &[], false), "centre"),
            // A NaN is null in the record, which is no number.
            (shape("lines", 0, &[(f64::NAN, 0.0)], false), "expected f64"),
            (shape("lines", -1, &[], false), "names no zone"),
            (shape("lines", 1 << 40, &[], false), "names no zone"),
        ] {
            let refused = round_trip(&request, Some(1)).1.unwrap_err();
            assert!(refused.contains(says), "{refused}");
        }
        let open = br#"{"id":2,"msg":{"type":"lines","shapeId":0,"points":[],"points2":[],
            "startPointWaits":[],"endPointWaits":[],"radius":0,"closed":false}}"#;
        assert!(
            decode(SET_REGION, open)
                .1
                .unwrap_err()
                .contains("closed true")
        );
        let extra = br#"{"id":3,"msg":{"type":"lines","shapeId":0,"points":[],"radius":0,
            "closed":false,"colour":"red"}}"#;
        assert!(decode(SET_SHAPE, extra).1.is_err());
    }

    #[test]
    fn old_recordings_decode_as_the_local_channel_read_them() {
        let (id, command) = decode("set_navi_cmd", br#"{"cmd":"1","distance":50}"#);
        assert_eq!(id, None);
        assert_eq!(
            command,
            Ok(Command::Move(MoveKind::Straight { distance_m: 0.5 }))
        );
        let (_, mission) = decode(
            "mission",
            br#"[{"action":"CHARGING","parameters":{"time":0}}]"#,
        );
        assert!(matches!(
            mission,
            Ok(Command::Mission {
                tag: Some(MotionTag { owner: OWNER, .. }),
                ..
            })
        ));
    }

    #[test]
    fn free_text_is_kept_cut_whoever_sent_it_and_a_wifi_password_has_no_place() {
        let long = "x".repeat(10_000);
        let kept = Ros1Request::RobotSsh {
            instruction: long.clone(),
        }
        .kept();
        assert_eq!(kept, Ros1Request::robot_ssh(&long));
        assert!(
            matches!(&kept, Ros1Request::RobotSsh { instruction } if instruction.chars().count() == SHOWN_INSTRUCTION)
        );
        let wifi = Ros1Request::SetWifi { wifi_name: long }.kept();
        assert!(
            matches!(&wifi, Ros1Request::SetWifi { wifi_name } if wifi_name.chars().count() == SHOWN_WIFI_NAME)
        );
        // A recorded /set_wifi holds its name and nothing else: a password is refused.
        let (id, asked) = adapter::decode_request::<SetWifi>(
            SET_WIFI,
            br#"{"id":1,"msg":{"wifi_name":"n","wifi_pass":"p"}}"#,
        );
        assert_eq!(id, Some(1));
        assert!(asked.is_err());
    }
}
