//! The ROS1 node's requests, typed: what each topic and service asks of the core, the form
//! the node records it in (its ROS name as the topic, `{"id": ID, "msg": MESSAGE}` with the
//! message's fields as JSON), and the adapter that hands it to the core and answers it.

use serde::{Deserialize, Serialize};

use super::{OWNER, SOURCE};
use crate::api::adapter::{self, RequestAdapter};
use crate::api::legacy;
use crate::api::requests::{self, Twist};
use crate::control::MotionTag;
use crate::vehicle::Command;

/// `/cmd_vel`'s name.
pub const CMD_VEL: &str = "/cmd_vel";
/// `/navi_stop`'s name.
pub const NAVI_STOP: &str = "/navi_stop";
/// `/autocharge`'s name.
pub const AUTOCHARGE: &str = "/autocharge";
/// `/set_navi_cmd`'s name.
pub const SET_NAVI_CMD: &str = "/set_navi_cmd";

/// A request of the node.
#[derive(Debug, Clone, PartialEq)]
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

    /// Its topic's or service's name.
    pub fn name(&self) -> &'static str {
        match self {
            Self::CmdVel { .. } => CMD_VEL,
            Self::NaviStop => NAVI_STOP,
            Self::Autocharge => AUTOCHARGE,
            Self::SetNaviCmd { .. } => SET_NAVI_CMD,
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
            Self::CmdVel { .. } | Self::NaviStop => false,
        }
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
        _ => (None, Err(format!("unknown topic {topic:?}"))),
    };
    (id, command.map(tagged))
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

/// The ROS1 node's adapter.
pub const ADAPTER: RequestAdapter = RequestAdapter::new(SOURCE, decode);

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
}
