//! What the sequencer says about a run besides its data: step starts
//! and ends as typed events (the log's `/steps`), and the severity of the
//! lines it writes for people (the log's `/events`, `foxglove.Log`).

use crate::procedure::Step;

pub use gyrobench_log::schema::{Level, PowerOn, PowerOnSource, StepEvent, StepPhase};

/// The event for step `s` at run-order position `index`.
pub fn step_event(t_s: f64, phase: StepPhase, index: usize, s: &Step) -> StepEvent {
    StepEvent {
        t_s,
        phase,
        index,
        key: s.key.clone(),
        line: s.line,
        group: s.group,
        action: s.kind.action().to_owned(),
        description: s.describe(),
        link: None,
        slot_links: Vec::new(),
        power_on: None,
    }
}
