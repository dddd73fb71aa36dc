//! What a run log holds: its topics, their JSON Schemas, and the message
//! types the writer serializes and every reader deserializes. One place, so
//! the writer and its readers cannot drift apart.
//!
//! Every message is JSON with a jsonschema schema, so Foxglove / Lichtblick
//! can plot any numeric field; the event log is `foxglove.Log`.

use serde::{Deserialize, Serialize};

use gyrobench_analysis::series::Interval;
use gyrobench_protocol::frame::LinkStats;

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
    pub link: Option<LinkStats>,
    /// At the end of a record of a batch: each other unit's link figures
    /// over it, in slot order (the first unit's are `link`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub slot_links: Vec<LinkStats>,
    /// At the end of a step that switched the unit on (a `power` step, or
    /// the run's own power-on at its start, logged as a restore): when.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub power_on: Option<PowerOn>,
}

/// The moment the unit was switched on, as the run knows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PowerOn {
    /// Device time, s since this part of the run started.
    pub t_s: f64,
    /// The same moment in UTC (RFC 3339).
    pub utc: String,
    /// How the run knows it.
    pub source: PowerOnSource,
}

/// How the run knows when the unit was switched on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PowerOnSource {
    /// The run switched the supply's output on, from off, and read it on.
    Switched,
    /// An operator switched the unit on and confirmed it at that moment
    /// (a bench without a supply).
    Operator,
    /// Not known: the unit was found powered, or a log older than the
    /// power-on record; the figures take the part's start.
    Assumed,
}

impl PowerOnSource {
    /// In words, for the report.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Switched => "switched on by the run, from off",
            Self::Operator => "switched on by the operator, who confirmed it then",
            Self::Assumed => "not known: taken as the start of the run",
        }
    }
}

/// Which group a step belongs to (the procedure's vocabulary, logged in
/// every [`StepEvent`]).
pub use gyrobench_model::procedure::Group;

/// Topics of a run log.
pub mod topics {
    /// Every gyro frame, batched per tick.
    pub const FRAMES: &str = "/gyro/frames";
    /// 1 Hz rate and temperatures for quick plots.
    pub const RATE_1HZ: &str = "/gyro/rate_1hz";
    /// Chamber state, 1 Hz.
    pub const CHAMBER: &str = "/chamber/state";
    /// Table state, orientation and Earth-rate projection, 1 Hz.
    pub const TABLE: &str = "/table/state";
    /// Notes, measurements and errors for people (foxglove.Log).
    pub const EVENTS: &str = "/events";
    /// Link statistics of the gyro.
    pub const LINK: &str = "/gyro/link";
    /// Step starts and ends, as data (format 2 on).
    pub const STEPS: &str = "/steps";
    /// The unit's supply channel, 1 Hz (benches with a supply).
    pub const SUPPLY: &str = "/supply/state";
}

/// The topics a batch's other units have each (under [`slot_topic`]): the
/// first unit of a batch is on the single-unit topics.
pub const SLOT_TOPICS: [&str; 4] = [
    topics::FRAMES,
    topics::RATE_1HZ,
    topics::TABLE,
    topics::LINK,
];

/// Unit `slot`'s own copy of `topic` in a batch's log: `/slots/B/gyro/frames`;
/// its `/table/state` is the table as that unit sees it (its orientation
/// and reference).
pub fn slot_topic(slot: &str, topic: &str) -> String {
    format!("/slots/{slot}{topic}")
}

/// Version of the log layout this build writes. Format 1 logs (no
/// `/steps`, no attachments) still replay; format 3 judges by a decision
/// rule (`FORMAT_JUDGED`).
pub const FORMAT: u32 = 3;

/// The first format whose runs were judged by a decision rule with each
/// figure's uncertainty, a procedure naming none judged guarded, and the
/// compensated drift on coefficients fitted held out. A log of an earlier
/// format is replayed as it was judged: by its limits alone, the drift
/// compensated in sample.
pub const FORMAT_JUDGED: u32 = 3;

/// Name of the metadata record with the run's configuration.
pub const RUN_META: &str = "run";
/// Name of the metadata record that says how the run ended.
pub const RESULT_META: &str = "result";
/// Attachment holding the procedure text the run executed.
pub const PROCEDURE_ATTACHMENT: &str = "procedure.toml";
/// Attachment holding the run's `report.json`.
pub const REPORT_ATTACHMENT: &str = "report.json";

/// (topic, schema name, JSON Schema) of every channel, in channel order.
pub const CHANNELS: [(&str, &str, &str); 8] = [
    (topics::FRAMES, "gyrobench.GyroFrames", FRAMES_SCHEMA),
    (topics::RATE_1HZ, "gyrobench.Rate1Hz", RATE_SCHEMA),
    (topics::CHAMBER, "gyrobench.ChamberState", CHAMBER_SCHEMA),
    (topics::TABLE, "gyrobench.TableState", TABLE_SCHEMA),
    (topics::EVENTS, "foxglove.Log", LOG_SCHEMA),
    (topics::LINK, "gyrobench.LinkStats", LINK_SCHEMA),
    (topics::STEPS, "gyrobench.StepEvent", STEP_SCHEMA),
    (topics::SUPPLY, "gyrobench.SupplyState", SUPPLY_SCHEMA),
];

const FRAMES_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.GyroFrames","description":"Consecutive gyro frames; element i of every array is frame i","properties":{"t0_s":{"type":"number","description":"device time of the first frame, s since the run started"},"dt_s":{"type":"number","description":"frame period, s"},"lsb_arcsec":{"type":"number"},"temp_lsb_c":{"type":"number"},"seq":{"type":"array","items":{"type":"integer"}},"counts":{"type":"array","items":{"type":"integer"},"description":"delta-angle counts"},"t1_raw":{"type":"array","items":{"type":"integer"}},"t2_raw":{"type":"array","items":{"type":"integer"}},"tcase_raw":{"type":"array","items":{"type":"integer"}},"status":{"type":"array","items":{"type":"integer"}}},"required":["t0_s","dt_s","lsb_arcsec","temp_lsb_c","seq","counts","t1_raw","t2_raw","tcase_raw","status"]}"#;
const RATE_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.Rate1Hz","properties":{"t_s":{"type":"number"},"rate_dph":{"type":"number","description":"measured rate, Earth rate included"},"reference_dph":{"type":"number","description":"Earth + table rate on the nominal axis"},"bias_dph":{"type":"number","description":"rate minus reference"},"t1_c":{"type":"number"},"t2_c":{"type":"number"},"tcase_c":{"type":"number"},"chamber_c":{"type":"number"},"frames":{"type":"integer"},"record":{"type":["string","null"]}},"required":["t_s","rate_dph","reference_dph","bias_dph","t1_c","t2_c","tcase_c","chamber_c","frames"]}"#;
const CHAMBER_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.ChamberState","properties":{"t_s":{"type":"number"},"air_c":{"type":"number"},"set_point_c":{"type":"number"},"mode":{"type":"string"},"alarms":{"type":"array","items":{"type":"integer"}}},"required":["t_s","air_c","set_point_c","mode","alarms"]}"#;
const TABLE_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.TableState","description":"The pose of the unit; the table axis angles are absent where they are not known (a run imported from another bench)","properties":{"t_s":{"type":"number"},"outer_deg":{"type":"number"},"inner_deg":{"type":"number"},"outer_rate_dps":{"type":"number"},"inner_rate_dps":{"type":"number"},"commanded_outer_deg":{"type":"number"},"commanded_inner_deg":{"type":"number"},"azimuth_deg":{"type":"number"},"elevation_deg":{"type":"number"},"roll_deg":{"type":"number"},"earth_rate_dph":{"type":"number"},"in_position":{"type":"boolean"},"step":{"type":"string"}},"required":["t_s","outer_rate_dps","inner_rate_dps","azimuth_deg","elevation_deg","roll_deg","earth_rate_dph","step"]}"#;
const SUPPLY_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.SupplyState","description":"The supply output the unit hangs on","properties":{"t_s":{"type":"number"},"v":{"type":"number","description":"voltage measured at the output, V"},"a":{"type":"number","description":"current measured, A"},"w":{"type":"number","description":"power delivered, W"},"set_v":{"type":"number","description":"voltage setting, V"},"limit_a":{"type":"number","description":"current limit, A"},"on":{"type":"boolean"},"tripped":{"type":"boolean","description":"over-current protection tripped"}},"required":["t_s","v","a","w","set_v","limit_a","on","tripped"]}"#;
const LOG_SCHEMA: &str = r#"{"type":"object","title":"foxglove.Log","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0}}},"level":{"type":"integer","description":"1 debug, 2 info, 3 warning, 4 error, 5 fatal"},"message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer"}},"required":["timestamp","level","message","name","file","line"]}"#;
const LINK_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.LinkStats","properties":{"t_s":{"type":"number"},"bytes":{"type":"integer"},"frames":{"type":"integer"},"resyncs":{"type":"integer"},"skipped_bytes":{"type":"integer"},"crc_errors":{"type":"integer"},"lost_frames":{"type":"integer"},"duplicates":{"type":"integer"},"reconnects":{"type":"integer"},"longest_gap_ms":{"type":"integer","description":"longest stretch without a valid frame, ms (host clock)"}},"required":["t_s","frames","lost_frames","crc_errors"]}"#;
const STEP_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.StepEvent","description":"A procedure step started, ended, or was run to restore a resumed run's conditions","properties":{"t_s":{"type":"number","description":"device time, s since this part of the run started"},"phase":{"type":"string","enum":["start","end","restore"]},"index":{"type":"integer","description":"position of the step in run order (setup, main, cleanup)"},"key":{"type":"string","description":"dotted key of the step in the procedure file"},"line":{"type":"integer"},"group":{"type":"string","enum":["setup","main","cleanup"]},"action":{"type":"string"},"description":{"type":"string"},"link":{"type":"object","description":"at the end of a record: the gyro link's figures over it"},"slot_links":{"type":"array","items":{"type":"object"},"description":"at the end of a record of a batch: each other unit's link figures over it, in slot order"},"power_on":{"type":"object","description":"at the end of a step that switched the unit on: when (t_s, device time; utc) and how the run knows it (source: switched or operator)","properties":{"t_s":{"type":"number"},"utc":{"type":"string"},"source":{"type":"string","enum":["switched","operator","assumed"]}}}},"required":["t_s","phase","index","key","line","group","action","description"]}"#;

/// `foxglove.Log` time stamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Timestamp {
    /// Seconds since the epoch.
    pub sec: u64,
    /// Nanoseconds.
    pub nsec: u32,
}

/// One `/events` message (`foxglove.Log`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogLine {
    /// Wall time of the event.
    pub timestamp: Timestamp,
    /// Severity.
    pub level: Level,
    /// Text for people.
    pub message: String,
    /// Who wrote it (`sequencer`).
    #[serde(default)]
    pub name: String,
    /// Unused (required by the schema).
    #[serde(default)]
    pub file: String,
    /// Unused (required by the schema).
    #[serde(default)]
    pub line: u32,
}

/// One `/gyro/rate_1hz` message: the 1 Hz interval as the recorder writes
/// it and every reader (replay, export, diagnose) reads it back.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rate1Hz {
    /// Device time at the end of the interval, s.
    pub t_s: f64,
    /// Mean rate, deg/h (Earth rate included).
    pub rate_dph: f64,
    /// Earth (+ table) rate on the axis, deg/h.
    pub reference_dph: f64,
    /// `rate_dph - reference_dph`.
    #[serde(default)]
    pub bias_dph: f64,
    /// Block sensor 1, degC.
    pub t1_c: f64,
    /// Block sensor 2, degC.
    pub t2_c: f64,
    /// Case, degC.
    pub tcase_c: f64,
    /// Chamber air, degC.
    pub chamber_c: f64,
    /// Frames in the interval (0 for an imported run).
    #[serde(default)]
    pub frames: u32,
    /// Record label while recording.
    #[serde(default)]
    pub record: Option<String>,
}

impl Rate1Hz {
    /// The message of an interval.
    pub fn new(iv: &Interval, record: Option<&str>) -> Self {
        Self {
            t_s: iv.time_s,
            rate_dph: iv.rate_dph,
            reference_dph: iv.reference_dph,
            bias_dph: iv.bias_dph(),
            t1_c: iv.t1_c,
            t2_c: iv.t2_c,
            tcase_c: iv.tcase_c,
            chamber_c: iv.chamber_c,
            frames: iv.frames,
            record: record.map(str::to_owned),
        }
    }

    /// The interval as logged.
    pub fn interval(&self) -> Interval {
        Interval {
            time_s: self.t_s,
            rate_dph: self.rate_dph,
            reference_dph: self.reference_dph,
            t1_c: self.t1_c,
            t2_c: self.t2_c,
            tcase_c: self.tcase_c,
            chamber_c: self.chamber_c,
            frames: self.frames,
        }
    }
}

/// One `/chamber/state` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChamberState {
    /// Device time, s.
    pub t_s: f64,
    /// Air temperature, degC.
    pub air_c: f64,
    /// Set point, degC.
    pub set_point_c: f64,
    /// `off`, `standby` or `constant`.
    pub mode: String,
    /// Active alarm codes.
    #[serde(default)]
    pub alarms: Vec<u16>,
}

/// One `/supply/state` message.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SupplyState {
    /// Device time, s.
    pub t_s: f64,
    /// Voltage measured, V.
    pub v: f64,
    /// Current measured, A.
    pub a: f64,
    /// Power delivered, W.
    pub w: f64,
    /// Voltage setting, V.
    pub set_v: f64,
    /// Current limit, A.
    pub limit_a: f64,
    /// Output on.
    pub on: bool,
    /// Over-current protection tripped.
    pub tripped: bool,
}

/// One `/table/state` message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableState {
    /// Device time, s.
    pub t_s: f64,
    /// Outer axis angle, deg (absent when not known: a run imported from
    /// another bench without its table angles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outer_deg: Option<f64>,
    /// Inner axis angle, deg (absent when not known).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inner_deg: Option<f64>,
    /// Outer axis rate, deg/s.
    pub outer_rate_dps: f64,
    /// Inner axis rate, deg/s.
    pub inner_rate_dps: f64,
    /// Outer angle last commanded, deg (absent when not known).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commanded_outer_deg: Option<f64>,
    /// Inner angle last commanded, deg (absent when not known).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub commanded_inner_deg: Option<f64>,
    /// Body azimuth, deg.
    pub azimuth_deg: f64,
    /// Body elevation, deg.
    pub elevation_deg: f64,
    /// Body roll, deg.
    pub roll_deg: f64,
    /// Earth + table rate on the nominal axis, deg/h.
    pub earth_rate_dph: f64,
    /// Both axes at their commanded angles and at rest.
    #[serde(default)]
    pub in_position: bool,
    /// Procedure step key.
    #[serde(default)]
    pub step: String,
}

/// One `/gyro/frames` message as written: every frame of one tick.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct GyroFrames {
    /// Device time of the first frame, s.
    pub t0_s: f64,
    /// Frame period, s.
    pub dt_s: f64,
    /// Angle per count, arcsec.
    pub lsb_arcsec: f64,
    /// Temperature per LSB, degC.
    pub temp_lsb_c: f64,
    /// Sequence counters.
    pub seq: Vec<u8>,
    /// Delta-angle counts.
    pub counts: Vec<i32>,
    /// T1 in temperature LSB.
    pub t1_raw: Vec<i16>,
    /// T2 in temperature LSB.
    pub t2_raw: Vec<i16>,
    /// Case temperature in temperature LSB.
    pub tcase_raw: Vec<i16>,
    /// Status bits.
    pub status: Vec<u16>,
}

/// One `/gyro/link` message.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LinkSample {
    /// Device time, s.
    pub t_s: f64,
    /// Figures so far.
    #[serde(flatten)]
    pub stats: LinkStats,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_schema_is_json_naming_its_own_title() {
        for (topic, name, schema) in CHANNELS {
            let v: serde_json::Value = serde_json::from_str(schema).expect(topic);
            assert_eq!(v["title"], name, "{topic}");
        }
    }

    #[test]
    fn a_step_event_round_trips_and_matches_its_schema_fields() {
        let e = StepEvent {
            t_s: 1.5,
            phase: StepPhase::Restore,
            index: 3,
            key: "main.2".into(),
            line: 12,
            group: Group::Main,
            action: "chamber".into(),
            description: "chamber to +20.0 degC".into(),
            link: None,
            slot_links: Vec::new(),
            power_on: Some(PowerOn {
                t_s: 1.5,
                utc: "2026-12-06T07:00:00Z".into(),
                source: PowerOnSource::Switched,
            }),
        };
        let text = serde_json::to_string(&e).expect("json");
        assert!(text.contains(r#""phase":"restore""#), "{text}");
        assert_eq!(serde_json::from_str::<StepEvent>(&text).expect("back"), e);
        let schema: serde_json::Value = serde_json::from_str(STEP_SCHEMA).expect("schema is JSON");
        let v: serde_json::Value = serde_json::from_str(&text).expect("json");
        for f in schema["required"].as_array().expect("required") {
            assert!(v.get(f.as_str().expect("name")).is_some(), "{f}");
        }
    }

    #[test]
    fn levels_are_the_foxglove_integers() {
        assert_eq!(serde_json::to_string(&Level::Warning).expect("json"), "3");
        assert_eq!(
            serde_json::from_str::<Level>("4").expect("level"),
            Level::Error
        );
        assert!(serde_json::from_str::<Level>("9").is_err());
    }
}
