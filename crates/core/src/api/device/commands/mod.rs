//! The device dialect's commands, one file each, found by their topic's last part in
//! [`COMMANDS`]. A handler reads the request's `data` into its typed request, hands the core
//! its command and says when the request is answered; a failure is a [`DeviceError`], whose
//! code the dialect answers with.

mod cancel;
mod estop;
pub(super) mod goal;
mod mapping;
mod reset;

use serde_json::Value;

use super::error::DeviceError;
use crate::api::mqtt::{CoreAccess, Publish};
pub(super) use goal::Goals;

/// What a handler works with besides the request's `data`.
pub(super) struct Context<'a> {
    /// The vehicle.
    pub core: &'a mut dyn CoreAccess,
    /// The command's name (`goal`).
    pub command: &'static str,
    /// The request's `msg_id`.
    pub msg_id: &'a Value,
    /// The request as it came, for what is passed on.
    pub payload: &'a [u8],
    /// The goals answered when they end.
    pub goals: &'a mut Goals,
    /// Where the navigation stack takes mapping requests, when one is configured.
    pub forward: Option<&'a str>,
    /// What is published besides the ack.
    pub out: &'a mut Vec<Publish>,
}

/// When a request is answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Answered {
    /// Now, as a success.
    Now,
    /// When the action it started ends (a goal).
    AtItsEnd,
    /// By whoever it was passed on to.
    Elsewhere,
}

/// A command's handler.
pub(super) type Handler = fn(&Value, &mut Context<'_>) -> Result<Answered, DeviceError>;

/// One command: its name (`device/{serial}/{name}`), whether chassisd carries it out itself,
/// and its handler.
pub(super) struct Entry {
    /// The topic's last part.
    pub name: &'static str,
    /// Carried out by chassisd (else passed to the navigation stack).
    pub own: bool,
    /// Its handler.
    pub handle: Handler,
}

const fn entry(name: &'static str, own: bool, handle: Handler) -> Entry {
    Entry { name, own, handle }
}

/// Every command: the spec's mapping requests, which belong to the navigation stack, then
/// chassisd's own. A new one is its file and a line here.
pub(super) const COMMANDS: [Entry; 7] = [
    entry("start_mapping", false, mapping::handle),
    entry("stop_mapping", false, mapping::handle),
    entry("use_map", false, mapping::handle),
    entry("goal", true, goal::handle),
    entry("estop", true, estop::handle),
    entry("reset", true, reset::handle),
    entry("cancel", true, cancel::handle),
];

/// The command called `name`.
pub(super) fn find(name: &str) -> Result<&'static Entry, DeviceError> {
    COMMANDS
        .iter()
        .find(|c| c.name == name)
        .ok_or_else(|| DeviceError::Unknown(name.to_owned()))
}

/// The commands the navigation stack takes.
pub(super) fn mapping() -> impl Iterator<Item = &'static str> {
    COMMANDS.iter().filter(|c| !c.own).map(|c| c.name)
}
