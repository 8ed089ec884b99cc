//! MISSION (5 on `cmd/navigation`): steps run in order, their progress notified on
//! `cmd/navigation/notify` with the request's `messageId`.

use std::collections::VecDeque;
use std::sync::Arc;

use serde_json::{Value, json};

use super::{Context, Done};
use crate::api::requests::mission_steps;
use crate::api::root::error::{OK, REFUSED, RootError};
use crate::control::mission::MissionEvent;
use crate::control::{MotionTag, Outcome};
use crate::vehicle::Command;

/// Mission `messageId`s kept for their notifies.
const MAX_PENDING: usize = 16;

/// The missions under way or recently ended: their tag's id and `messageId`.
#[derive(Default)]
pub(in crate::api::root) struct Missions {
    pending: VecDeque<(u64, Value)>,
    last: u64,
}

impl Missions {
    /// The tag of the next mission.
    fn next_tag(&mut self) -> MotionTag {
        self.last += 1;
        MotionTag {
            owner: "root",
            id: self.last,
        }
    }

    /// Notes a started mission, forgetting the oldest beyond [`MAX_PENDING`].
    fn started(&mut self, tag: MotionTag, message_id: Value) {
        if self.pending.len() >= MAX_PENDING {
            self.pending.pop_front();
        }
        self.pending.push_back((tag.id, message_id));
    }

    /// The `messageId` and notify `data` for `event` of the mission tagged `id`; `None` when
    /// it is not one of root's missions (or long forgotten).
    pub(in crate::api::root) fn progress(
        &mut self,
        id: u64,
        event: &MissionEvent,
    ) -> Option<(Value, Value)> {
        let (_, message_id) = self.pending.iter().find(|(m, _)| *m == id).cloned()?;
        let data = match event {
            MissionEvent::StepStarted(step, action) => {
                json!({"code": OK, "step": step, "action": action, "state": "started"})
            }
            MissionEvent::StepDone(step, action) => {
                json!({"code": OK, "step": step, "action": action, "state": "done"})
            }
            MissionEvent::Ended(Outcome::Succeeded) => json!({"code": OK}),
            MissionEvent::Ended(other) => {
                json!({"code": REFUSED, "message": format!("mission {other}")})
            }
        };
        if matches!(event, MissionEvent::Ended(_)) {
            self.pending.retain(|(m, _)| *m != id);
        }
        Some((message_id, data))
    }
}

pub(super) fn handle(data: &Value, cx: &mut Context<'_>) -> Result<Done, RootError> {
    let steps = mission_steps(data).map_err(RootError::Invalid)?;
    let tag = cx.missions.next_tag();
    cx.core.command(Command::Mission {
        steps: Arc::new(steps),
        tag: Some(tag),
    })?;
    cx.missions.started(tag, cx.message_id.clone());
    Ok(Done::Acked)
}
