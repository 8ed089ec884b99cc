//! The root dialect's commands, one file each, found by their topic and `messageType` in
//! [`COMMANDS`]. A handler reads the request's `data` into its typed request, hands the core
//! its command and says what follows the ack; a failure is a [`RootError`], whose code the
//! dialect answers with.

mod drive;
mod estop;
mod init_position;
mod mapping;
pub(crate) mod mission;
mod pause;
mod reset;
mod resume;
mod set_lng_lat;
mod set_map;
mod switch_mode;

use serde_json::Value;

use super::error::RootError;
use crate::api::mqtt::CoreAccess;
pub(super) use mission::Missions;

/// What a handler works with besides the request's `data`.
pub(super) struct Context<'a> {
    /// The vehicle.
    pub core: &'a mut dyn CoreAccess,
    /// The request's `messageId`, for answers that come later.
    pub message_id: &'a Value,
    /// The missions whose progress is notified.
    pub missions: &'a mut Missions,
}

/// What follows a command's ack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Done {
    /// Nothing, or notifies when the action progresses (a mission).
    Acked,
    /// A `notify` at once: the action the protocol reports the end of is already done.
    Finished,
}

/// A command's handler.
pub(super) type Handler = fn(&Value, &mut Context<'_>) -> Result<Done, RootError>;

/// One command: where it is taken and who handles it.
pub(super) struct Entry {
    /// The topic's base (`cmd/navigation` for `/root/{id}/cmd/navigation/set`).
    pub base: &'static str,
    /// Its `messageType`.
    pub kind: u64,
    /// The spec's name for it.
    pub name: &'static str,
    /// Its handler.
    pub handle: Handler,
}

const fn entry(base: &'static str, kind: u64, name: &'static str, handle: Handler) -> Entry {
    Entry {
        base,
        kind,
        name,
        handle,
    }
}

/// Every command, in the order of the spec's topics; a new one is its file and a line here.
pub(super) const COMMANDS: [Entry; 12] = [
    entry("cmd/navigation", 0, "INIT_POSITION", init_position::handle),
    entry("cmd/navigation", 1, "PAUSE", pause::handle),
    entry("cmd/navigation", 2, "CONTINUE", resume::handle),
    entry("cmd/navigation", 5, "MISSION", mission::handle),
    entry("cmd/navigation", 6, "SWITCH_MODE", switch_mode::handle),
    entry("cmd/map", 3, "MAPPING_START", mapping::handle),
    entry("cmd/map", 4, "MAPPING_STOP", mapping::handle),
    entry("cmd/chassis", 100, "DRIVE", drive::handle),
    entry("cmd/chassis", 101, "ESTOP", estop::handle),
    entry("cmd/chassis", 102, "RESET", reset::handle),
    entry("setting/map", 0, "SET_MAP", set_map::handle),
    entry(
        "setting/navigation",
        100,
        "SET_LNG_LAT",
        set_lng_lat::handle,
    ),
];

/// The command of `messageType` `kind` on `{base}/set`.
pub(super) fn find(base: &str, kind: u64) -> Result<&'static Entry, RootError> {
    COMMANDS
        .iter()
        .find(|c| c.base == base && c.kind == kind)
        .ok_or_else(|| RootError::UnknownType {
            base: base.to_owned(),
            kind,
        })
}

/// The topic bases commands are taken on, each once, in the table's order.
pub(super) fn bases() -> Vec<&'static str> {
    let mut bases: Vec<&'static str> = Vec::new();
    for c in &COMMANDS {
        if !bases.contains(&c.base) {
            bases.push(c.base);
        }
    }
    bases
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_command_is_found_by_its_topic_and_type_only() {
        for c in &COMMANDS {
            assert_eq!(find(c.base, c.kind).map(|e| e.name), Ok(c.name));
            let twice = COMMANDS
                .iter()
                .filter(|o| o.base == c.base && o.kind == c.kind)
                .count();
            assert_eq!(twice, 1, "{} is in the table twice", c.name);
        }
        let wrong_topic = find("cmd/chassis", 5).map(|e| e.name).unwrap_err();
        assert_eq!(wrong_topic.code(), super::super::error::UNKNOWN_TYPE);
        assert_eq!(
            bases(),
            [
                "cmd/navigation",
                "cmd/map",
                "cmd/chassis",
                "setting/map",
                "setting/navigation"
            ]
        );
    }
}
