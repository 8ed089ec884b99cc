//! The ROS1 services that ask rather than command, answered through the engine like every
//! request (so a recording keeps them and replays their answers): `/get_position` and
//! `/navi_info` read the vehicle, `/robot_ssh` and `/set_wifi` are refused, always.

use serde::{Deserialize, Serialize};
use serde_json::json;

use super::publisher;
use crate::api::adapter::{Answer, CoreAccess, decode_request};

/// `/get_position`'s name.
pub const GET_POSITION: &str = "/get_position";
/// `/navi_info`'s name.
pub const NAVI_INFO: &str = "/navi_info";
/// `/robot_ssh`'s name.
pub const ROBOT_SSH: &str = "/robot_ssh";
/// `/set_wifi`'s name.
pub const SET_WIFI: &str = "/set_wifi";

/// A request without fields (`/get_position`, `/navi_info`) as JSON.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Empty {}

/// map_msgs/RobotSsh's request as chassisd records it.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSsh {
    /// The shell command, cut.
    pub instruction: String,
}

/// map_msgs/SetWifi's request as chassisd records it: the name only.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SetWifi {
    /// The network's name, cut.
    pub wifi_name: String,
}

/// Why `/robot_ssh` and `/set_wifi` answer no.
pub const DISABLED: &str = "disabled for security";

/// The answer to the query on `topic` (`about`: `/navi_info`'s), reading `core`; `None`
/// when `topic` is a command's.
pub fn answer(topic: &str, payload: &[u8], about: &str, core: &dyn CoreAccess) -> Option<Answer> {
    let (request, result, data) = match topic {
        GET_POSITION => {
            let (id, asked) = decode_request::<Empty>(topic, payload);
            let place = asked.and_then(|_| {
                publisher::position(&core.pose_report()).ok_or_else(|| {
                    "the vehicle is not located yet (no GNSS fix or INIT_POSITION)".to_owned()
                })
            });
            match place {
                Ok(p) => (id, Ok(()), Some(json!({ "x": p.x, "y": p.y }))),
                Err(why) => (id, Err(why), None),
            }
        }
        NAVI_INFO => {
            let (id, asked) = decode_request::<Empty>(topic, payload);
            match asked {
                Ok(Empty {}) => (id, Ok(()), Some(json!(about))),
                Err(why) => (id, Err(why), None),
            }
        }
        ROBOT_SSH => {
            let (id, asked) = decode_request::<RobotSsh>(topic, payload);
            let why =
                asked.and_then(|_| Err(format!("{DISABLED}: chassisd runs no remote commands")));
            (id, why, None)
        }
        SET_WIFI => {
            let (id, asked) = decode_request::<SetWifi>(topic, payload);
            let why = asked.and_then(|_| {
                Err(format!(
                    "{DISABLED}: chassisd has no network manager integration"
                ))
            });
            (id, why, None)
        }
        _ => return None,
    };
    Some(Answer {
        topic: topic.to_owned(),
        request,
        result,
        data,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::api::adapter::encode_request;
    use crate::vehicle::chassis::CommandRejected;
    use crate::vehicle::{Command, Localization, Pose2D, PoseCovariance, PoseReport};

    /// The core's answer to queries: a pose report, and no commands taken.
    struct Placed(PoseReport);

    impl CoreAccess for Placed {
        fn pose_report(&self) -> PoseReport {
            self.0
        }

        fn command(&mut self, _: Command) -> Result<(), CommandRejected> {
            Err(CommandRejected::NoDrives)
        }
    }

    fn report(localization: Localization) -> PoseReport {
        PoseReport {
            odom: None,
            map: Some((
                Pose2D {
                    x: 1.5,
                    y: -2.0,
                    yaw: 0.3,
                },
                PoseCovariance::default(),
            )),
            frames: None,
            localization,
        }
    }

    fn ask(topic: &str, payload: &[u8], core: &Placed) -> Answer {
        answer(topic, payload, "{\"numero\":\"yard-7\"}", core).expect("a query")
    }

    #[test]
    fn the_position_is_the_map_pose_once_located_with_the_request_s_id() {
        let located = Placed(report(Localization::Good));
        let a = ask(GET_POSITION, &encode_request(Some(7), &Empty {}), &located);
        assert_eq!(a.request, Some(7));
        assert_eq!(a.result, Ok(()));
        assert_eq!(a.data, Some(json!({"x": 1.5, "y": -2.0})));
        let unplaced = Placed(report(Localization::Uninitialized));
        let a = ask(GET_POSITION, &encode_request(Some(8), &Empty {}), &unplaced);
        assert!(a.result.is_err_and(|why| why.contains("not located")));
        assert_eq!(a.data, None);
    }

    #[test]
    fn about_is_the_build_and_the_shell_and_wifi_are_refused_whatever_is_asked() {
        let core = Placed(report(Localization::Good));
        let a = ask(NAVI_INFO, &encode_request(Some(1), &Empty {}), &core);
        assert_eq!(a.data, Some(json!("{\"numero\":\"yard-7\"}")));
        let ssh = RobotSsh {
            instruction: "reboot".into(),
        };
        let a = ask(ROBOT_SSH, &encode_request(Some(2), &ssh), &core);
        assert_eq!(a.request, Some(2));
        assert!(a.result.is_err_and(|why| why.starts_with(DISABLED)));
        let wifi = SetWifi {
            wifi_name: "yard-net".into(),
        };
        let a = ask(SET_WIFI, &encode_request(Some(3), &wifi), &core);
        assert!(a.result.is_err_and(|why| why.starts_with(DISABLED)));
    }

    #[test]
    fn a_malformed_query_is_refused_with_its_id_and_a_command_is_not_a_query() {
        let core = Placed(report(Localization::Good));
        let a = ask(GET_POSITION, br#"{"id": 4, "msg": {"extra": 1}}"#, &core);
        assert_eq!(a.request, Some(4));
        assert!(a.result.is_err());
        assert!(answer("/set_navi_cmd", b"{}", "", &core).is_none());
    }
}
