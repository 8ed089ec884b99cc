//! The rtk dialect's `mqtt_control` commands, one file per group, found by their `cmd` in
//! [`COMMANDS`] with the `cmd_type` each belongs to. A handler reads the message's fields,
//! acts on the trajectory store or the core, and says whether a `_success` feedback follows;
//! a failure is an [`RtkError`], answered `<cmd>_failse` with its reason.

mod task;
mod trajectories;

use super::error::RtkError;
use crate::api::mqtt::{CoreAccess, Publish};
use crate::api::request_body::Fields;
use crate::api::trajectory::TrajectoryStore;

/// What a handler works with besides the message.
pub(super) struct Context<'a> {
    /// The vehicle.
    pub core: &'a mut dyn CoreAccess,
    /// Where trajectories are kept.
    pub store: &'a mut dyn TrajectoryStore,
    /// The link's payload limit, bytes (an answer must fit the link's packet limit).
    pub max_payload: usize,
    /// What is published besides the feedback.
    pub out: &'a mut Vec<Publish>,
}

/// How a command that succeeded is answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Answered {
    /// By a `<cmd>_success` feedback.
    Feedback,
    /// By what it published (the protocol has no success feedback for it).
    Published,
}

/// A command's handler.
pub(super) type Handler = fn(&Fields, &mut Context<'_>) -> Result<Answered, RtkError>;

/// One command: its `cmd`, its `cmd_type` and its handler.
pub(super) struct Entry {
    /// Its `cmd`.
    pub cmd: &'static str,
    /// The `cmd_type` it must come with.
    pub cmd_type: &'static str,
    /// Its handler.
    pub handle: Handler,
}

const TRAJECTORY: &str = "trajectory_control";
const TASK: &str = "task_control";

const fn entry(cmd: &'static str, cmd_type: &'static str, handle: Handler) -> Entry {
    Entry {
        cmd,
        cmd_type,
        handle,
    }
}

/// Every command, in the order of the protocol; a new one is its handler and a line here.
pub(super) const COMMANDS: [Entry; 7] = [
    entry("get_all_trajectory", TRAJECTORY, trajectories::get_all),
    entry("save_trajectory", TRAJECTORY, trajectories::save),
    entry("delete_trajectory", TRAJECTORY, trajectories::delete),
    entry(
        "delete_all_trajectory",
        TRAJECTORY,
        trajectories::delete_all,
    ),
    entry("start_task", TASK, task::start),
    entry("cancel_task", TASK, task::cancel),
    entry("init_rtk_data", TASK, task::init_rtk_data),
];

/// The command `cmd`.
pub(super) fn find(cmd: &str) -> Result<&'static Entry, RtkError> {
    COMMANDS
        .iter()
        .find(|c| c.cmd == cmd)
        .ok_or_else(|| RtkError::Unknown(cmd.to_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_found_by_name_with_their_type() {
        assert_eq!(find("start_task").map(|c| c.cmd_type).ok(), Some(TASK));
        assert_eq!(
            find("save_trajectory").map(|c| c.cmd_type).ok(),
            Some(TRAJECTORY)
        );
        let unknown = find("fly").map(|c| c.cmd).unwrap_err();
        assert_eq!(unknown.to_string(), "unknown command \"fly\"");
    }
}
