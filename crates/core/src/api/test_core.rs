//! The core as the dialects' unit tests see it: it records every command and refuses the next
//! one with a chosen reason.

use super::adapter::CoreAccess;
use crate::vehicle::chassis::CommandRejected;
use crate::vehicle::{Command, PoseReport};

/// Commands in, each accepted unless a refusal is pending.
#[derive(Default)]
pub struct CommandLog {
    /// Every command handed in, in order.
    pub commands: Vec<Command>,
    /// The answer to the next command, once.
    pub refuse_next: Option<CommandRejected>,
}

impl CoreAccess for CommandLog {
    fn pose_report(&self) -> PoseReport {
        PoseReport::default()
    }

    fn command(&mut self, command: Command) -> Result<(), CommandRejected> {
        self.commands.push(command);
        self.refuse_next.take().map_or(Ok(()), Err)
    }
}
