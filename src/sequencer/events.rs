//! What the sequencer says about a run besides its data: step starts
//! and ends as typed events (the log's `/steps`), and the severity of the
//! lines it writes for people (the log's `/events`, `foxglove.Log`).

use serde::{Deserialize, Serialize};

use crate::procedure::{Group, Step};

/// Severity of an `/events` line (the `foxglove.Log` levels).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(into = "u8", try_from = "u8")]
pub enum Level {
    /// Step starts and ends, restore steps.
    Debug = 1,
    /// Notes, passing measurements, operator confirmations.
    Info = 2,
    /// Failing measurements, a run stopping.
    Warning = 3,
    /// The error that ended a run, failed cleanup steps.
    Error = 4,
    /// Not written by gyrobench; read for completeness.
    Fatal = 5,
}

impl From<Level> for u8 {
    fn from(l: Level) -> u8 {
        l as u8
    }
}

impl TryFrom<u8> for Level {
    type Error = String;
    fn try_from(v: u8) -> Result<Self, String> {
        Ok(match v {
            1 => Self::Debug,
            2 => Self::Info,
            3 => Self::Warning,
            4 => Self::Error,
            5 => Self::Fatal,
            _ => return Err(format!("log level {v} is not 1..5")),
        })
    }
}

/// What happened to a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepPhase {
    /// The step started.
    Start,
    /// The step completed.
    End,
    /// The step was run again to restore the conditions a resumed run
    /// needs; it is not one of the procedure's steps of this part.
    Restore,
}

/// One `/steps` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepEvent {
    /// Device time, s since this part of the run started.
    pub t_s: f64,
    /// Start, end or restore.
    pub phase: StepPhase,
    /// Position of the step in run order (setup, main, cleanup).
    pub index: usize,
    /// Dotted key in the procedure file (steps of a repeat share it).
    pub key: String,
    /// Line in the procedure file.
    pub line: usize,
    /// Setup, main or cleanup.
    pub group: Group,
    /// The step's `action`.
    pub action: String,
    /// The step in words.
    pub description: String,
    /// At the end of a record: the gyro link's figures over it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link: Option<crate::protocol::frame::LinkStats>,
    /// At the end of a record of a batch: each other unit's link figures
    /// over it, in slot order (the first unit's are `link`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub slot_links: Vec<crate::protocol::frame::LinkStats>,
}

impl StepEvent {
    /// The event for step `s` at run-order position `index`.
    pub fn new(t_s: f64, phase: StepPhase, index: usize, s: &Step) -> Self {
        Self {
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
        }
    }
}
