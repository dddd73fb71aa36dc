//! The run log: one MCAP file per run (`docs/log.md`).
//!
//! JSON messages with jsonschema schemas, so Foxglove / Lichtblick can plot
//! any numeric field; the event log as `foxglove.Log`. Gyro frames are
//! batched one message per tick (arrays per field) and zstd-compressed in
//! chunks; a chunk is closed at least every second of wall time so a crash
//! loses at most the last second. `finish()` writes the summary and index.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use mcap::records::MessageHeader;
use serde::{Deserialize, Serialize};

use crate::analysis::series::Interval;
use crate::clock::Stopwatch;
use crate::sequencer::{Sink, Tick};

/// Topics, schemas and their JSON Schema text.
pub mod topics {
    /// Every gyro frame, batched per tick.
    pub const FRAMES: &str = "/gyro/frames";
    /// 1 Hz rate and temperatures for quick plots.
    pub const RATE_1HZ: &str = "/gyro/rate_1hz";
    /// Chamber state, 1 Hz.
    pub const CHAMBER: &str = "/chamber/state";
    /// Table state, orientation and Earth-rate projection, 1 Hz.
    pub const TABLE: &str = "/table/state";
    /// Step events, notes and errors (foxglove.Log).
    pub const EVENTS: &str = "/events";
    /// Link statistics of the gyro.
    pub const LINK: &str = "/gyro/link";
}

const FRAMES_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.GyroFrames","description":"Consecutive gyro frames; element i of every array is frame i","properties":{"t0_s":{"type":"number","description":"device time of the first frame, s since the run started"},"dt_s":{"type":"number","description":"frame period, s"},"lsb_arcsec":{"type":"number"},"temp_lsb_c":{"type":"number"},"seq":{"type":"array","items":{"type":"integer"}},"counts":{"type":"array","items":{"type":"integer"},"description":"delta-angle counts"},"t1_raw":{"type":"array","items":{"type":"integer"}},"t2_raw":{"type":"array","items":{"type":"integer"}},"tcase_raw":{"type":"array","items":{"type":"integer"}},"status":{"type":"array","items":{"type":"integer"}}},"required":["t0_s","dt_s","lsb_arcsec","temp_lsb_c","seq","counts","t1_raw","t2_raw","tcase_raw","status"]}"#;
const RATE_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.Rate1Hz","properties":{"t_s":{"type":"number"},"rate_dph":{"type":"number","description":"measured rate, Earth rate included"},"reference_dph":{"type":"number","description":"Earth + table rate on the nominal axis"},"bias_dph":{"type":"number","description":"rate minus reference"},"t1_c":{"type":"number"},"t2_c":{"type":"number"},"tcase_c":{"type":"number"},"chamber_c":{"type":"number"},"frames":{"type":"integer"},"record":{"type":["string","null"]}},"required":["t_s","rate_dph","reference_dph","bias_dph","t1_c","t2_c","tcase_c","chamber_c","frames"]}"#;
const CHAMBER_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.ChamberState","properties":{"t_s":{"type":"number"},"air_c":{"type":"number"},"set_point_c":{"type":"number"},"mode":{"type":"string"},"alarms":{"type":"array","items":{"type":"integer"}}},"required":["t_s","air_c","set_point_c","mode","alarms"]}"#;
const TABLE_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.TableState","properties":{"t_s":{"type":"number"},"outer_deg":{"type":"number"},"inner_deg":{"type":"number"},"outer_rate_dps":{"type":"number"},"inner_rate_dps":{"type":"number"},"commanded_outer_deg":{"type":"number"},"commanded_inner_deg":{"type":"number"},"azimuth_deg":{"type":"number"},"elevation_deg":{"type":"number"},"roll_deg":{"type":"number"},"earth_rate_dph":{"type":"number"},"in_position":{"type":"boolean"},"step":{"type":"string"}},"required":["t_s","outer_deg","inner_deg","outer_rate_dps","inner_rate_dps","commanded_outer_deg","commanded_inner_deg","azimuth_deg","elevation_deg","roll_deg","earth_rate_dph","step"]}"#;
const LOG_SCHEMA: &str = r#"{"type":"object","title":"foxglove.Log","properties":{"timestamp":{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0}}},"level":{"type":"integer","description":"1 debug, 2 info, 3 warning, 4 error, 5 fatal"},"message":{"type":"string"},"name":{"type":"string"},"file":{"type":"string"},"line":{"type":"integer"}},"required":["timestamp","level","message","name","file","line"]}"#;
const LINK_SCHEMA: &str = r#"{"type":"object","title":"gyrobench.LinkStats","properties":{"t_s":{"type":"number"},"bytes":{"type":"integer"},"frames":{"type":"integer"},"resyncs":{"type":"integer"},"skipped_bytes":{"type":"integer"},"crc_errors":{"type":"integer"},"lost_frames":{"type":"integer"},"duplicates":{"type":"integer"}},"required":["t_s","frames","lost_frames","crc_errors"]}"#;

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

/// The parts of a `/table/state` message the readers of a run's
/// orientation use.
#[derive(Debug, Clone, Deserialize)]
pub struct TablePose {
    /// Body azimuth, deg.
    pub azimuth_deg: f64,
    /// Body elevation, deg.
    pub elevation_deg: f64,
    /// Body roll, deg.
    pub roll_deg: f64,
    /// Procedure step key.
    #[serde(default)]
    pub step: String,
}

/// Run metadata stored in the file (an MCAP metadata record named `run`).
#[derive(Debug, Clone, Default)]
pub struct RunMeta {
    /// Every key/value, e.g. `procedure_toml`, `bench_toml`, `twin_toml`,
    /// `site`, `dut_serial`, `software_version`, `start_time_utc`, `seed`.
    pub entries: BTreeMap<String, String>,
}

/// Writes a run's MCAP file.
pub struct Recorder {
    w: mcap::Writer<BufWriter<File>>,
    ch: BTreeMap<&'static str, u16>,
    seq: u32,
    start_ns: u64,
    frame_dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
    since_flush: Stopwatch,
    buf: Vec<u8>,
    messages: BTreeMap<&'static str, u64>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

fn mcap_err(e: mcap::McapError) -> std::io::Error {
    std::io::Error::other(e)
}

#[derive(Serialize)]
struct FramesMsg {
    t0_s: f64,
    dt_s: f64,
    lsb_arcsec: f64,
    temp_lsb_c: f64,
    seq: Vec<u8>,
    counts: Vec<i32>,
    t1_raw: Vec<i16>,
    t2_raw: Vec<i16>,
    tcase_raw: Vec<i16>,
    status: Vec<u16>,
}

impl Recorder {
    /// Create `path` and write the header, schemas, channels and metadata.
    /// `start_ns` is the wall time of device time zero (ns since the epoch).
    pub fn create(
        path: &Path,
        meta: &RunMeta,
        start_ns: u64,
        frame_dt_s: f64,
        lsb_arcsec: f64,
        temp_lsb_c: f64,
    ) -> std::io::Result<Self> {
        let file = File::create(path)?;
        let opts = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(4 * 1024 * 1024))
            .profile("")
            .library(format!("gyrobench {}", env!("CARGO_PKG_VERSION")));
        let mut w = opts.create(BufWriter::new(file)).map_err(mcap_err)?;
        let mut ch = BTreeMap::new();
        for (topic, name, schema) in [
            (topics::FRAMES, "gyrobench.GyroFrames", FRAMES_SCHEMA),
            (topics::RATE_1HZ, "gyrobench.Rate1Hz", RATE_SCHEMA),
            (topics::CHAMBER, "gyrobench.ChamberState", CHAMBER_SCHEMA),
            (topics::TABLE, "gyrobench.TableState", TABLE_SCHEMA),
            (topics::EVENTS, "foxglove.Log", LOG_SCHEMA),
            (topics::LINK, "gyrobench.LinkStats", LINK_SCHEMA),
        ] {
            let sid = w
                .add_schema(name, "jsonschema", schema.as_bytes())
                .map_err(mcap_err)?;
            let cid = w
                .add_channel(sid, topic, "json", &BTreeMap::new())
                .map_err(mcap_err)?;
            ch.insert(topic, cid);
        }
        w.write_metadata(&mcap::records::Metadata {
            name: "run".into(),
            metadata: meta.entries.clone(),
        })
        .map_err(mcap_err)?;
        Ok(Self {
            w,
            ch,
            seq: 0,
            start_ns,
            frame_dt_s,
            lsb_arcsec,
            temp_lsb_c,
            since_flush: Stopwatch::start(),
            buf: Vec::with_capacity(64 * 1024),
            messages: BTreeMap::new(),
        })
    }

    fn write_json(
        &mut self,
        topic: &'static str,
        t_s: f64,
        value: &impl Serialize,
    ) -> std::io::Result<()> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value)?;
        let time = self.start_ns + (t_s.max(0.0) * 1e9) as u64;
        self.seq += 1;
        let header = MessageHeader {
            channel_id: self.ch[topic],
            sequence: self.seq,
            log_time: time,
            publish_time: time,
        };
        self.w
            .write_to_known_channel(&header, &self.buf)
            .map_err(mcap_err)?;
        *self.messages.entry(topic).or_default() += 1;
        if self.since_flush.elapsed_s() >= 1.0 {
            self.w.flush().map_err(mcap_err)?;
            self.since_flush.lap_s();
        }
        Ok(())
    }

    /// Messages written per topic.
    pub fn message_counts(&self) -> &BTreeMap<&'static str, u64> {
        &self.messages
    }

    /// Write a metadata record (`result` at the end of a run: how it ended,
    /// which a replay cannot recompute from the data).
    pub fn metadata(
        &mut self,
        name: &str,
        entries: BTreeMap<String, String>,
    ) -> std::io::Result<()> {
        self.w
            .write_metadata(&mcap::records::Metadata {
                name: name.into(),
                metadata: entries,
            })
            .map_err(mcap_err)
    }

    /// Write the summary, indexes and footer; the file is complete.
    pub fn finish(mut self) -> std::io::Result<()> {
        self.w.finish().map_err(mcap_err)?;
        Ok(())
    }
}

impl Sink for Recorder {
    fn link(&mut self, t_s: f64, s: &crate::protocol::frame::LinkStats) -> std::io::Result<()> {
        #[derive(Serialize)]
        struct L<'a> {
            t_s: f64,
            #[serde(flatten)]
            s: &'a crate::protocol::frame::LinkStats,
        }
        self.write_json(topics::LINK, t_s, &L { t_s, s })
    }

    fn tick(&mut self, tick: &Tick, _record: Option<&str>, step: &str) -> std::io::Result<()> {
        if !tick.frames.is_empty() {
            let f = &tick.frames;
            let msg = FramesMsg {
                t0_s: tick.t0_s,
                dt_s: self.frame_dt_s,
                lsb_arcsec: self.lsb_arcsec,
                temp_lsb_c: self.temp_lsb_c,
                seq: f.iter().map(|x| x.seq).collect(),
                counts: f.iter().map(|x| x.counts).collect(),
                t1_raw: f.iter().map(|x| x.temps_raw[0]).collect(),
                t2_raw: f.iter().map(|x| x.temps_raw[1]).collect(),
                tcase_raw: f.iter().map(|x| x.temps_raw[2]).collect(),
                status: f.iter().map(|x| x.status).collect(),
            };
            self.write_json(topics::FRAMES, tick.t0_s, &msg)?;
        }
        if let Some(s) = &tick.state {
            #[derive(Serialize)]
            struct C<'a> {
                t_s: f64,
                air_c: f64,
                set_point_c: f64,
                mode: String,
                alarms: &'a [u16],
            }
            self.write_json(
                topics::CHAMBER,
                s.t_s,
                &C {
                    t_s: s.t_s,
                    air_c: s.chamber.air_c,
                    set_point_c: s.chamber.set_point_c,
                    mode: format!("{:?}", s.chamber.mode).to_lowercase(),
                    alarms: &s.chamber.alarms,
                },
            )?;
            #[derive(Serialize)]
            struct T<'a> {
                t_s: f64,
                outer_deg: f64,
                inner_deg: f64,
                outer_rate_dps: f64,
                inner_rate_dps: f64,
                commanded_outer_deg: f64,
                commanded_inner_deg: f64,
                azimuth_deg: f64,
                elevation_deg: f64,
                roll_deg: f64,
                earth_rate_dph: f64,
                in_position: bool,
                step: &'a str,
            }
            self.write_json(
                topics::TABLE,
                s.t_s,
                &T {
                    t_s: s.t_s,
                    outer_deg: s.table.angles.outer_deg,
                    inner_deg: s.table.angles.inner_deg,
                    outer_rate_dps: s.table.rates.outer_deg,
                    inner_rate_dps: s.table.rates.inner_deg,
                    commanded_outer_deg: s.commanded.outer_deg,
                    commanded_inner_deg: s.commanded.inner_deg,
                    azimuth_deg: s.orientation.azimuth_deg,
                    elevation_deg: s.orientation.elevation_deg,
                    roll_deg: s.orientation.roll_deg,
                    earth_rate_dph: s.reference_dph,
                    in_position: s.in_position,
                    step,
                },
            )?;
        }
        Ok(())
    }

    fn interval(&mut self, iv: &Interval, record: Option<&str>) -> std::io::Result<()> {
        self.write_json(topics::RATE_1HZ, iv.time_s, &Rate1Hz::new(iv, record))
    }

    fn event(&mut self, t_s: f64, level: u8, message: &str) -> std::io::Result<()> {
        #[derive(Serialize)]
        struct Ts {
            sec: u64,
            nsec: u32,
        }
        #[derive(Serialize)]
        struct Log<'a> {
            timestamp: Ts,
            level: u8,
            message: &'a str,
            name: &'a str,
            file: &'a str,
            line: u32,
        }
        let ns = self.start_ns + (t_s.max(0.0) * 1e9) as u64;
        self.write_json(
            topics::EVENTS,
            t_s,
            &Log {
                timestamp: Ts {
                    sec: ns / 1_000_000_000,
                    nsec: (ns % 1_000_000_000) as u32,
                },
                level,
                message,
                name: "sequencer",
                file: "",
                line: 0,
            },
        )
    }
}

/// What [`recover`] salvaged.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Recovered {
    /// Messages copied.
    pub messages: u64,
    /// Gyro frames inside the copied `/gyro/frames` messages.
    pub frames: u64,
    /// Bytes of the input after the last complete record (lost).
    pub bytes_lost: u64,
    /// Whether the input was complete already (had its footer).
    pub was_complete: bool,
}

/// Rewrite a possibly truncated log (a run killed mid-way) as a complete,
/// indexed file: every message of every complete chunk and the run
/// metadata are copied; what follows the last complete record is lost.
pub fn recover(input: &[u8], out: &Path) -> std::io::Result<Recovered> {
    use mcap::read::{LinearReader, MessageStream, Options};
    let lenient = || Options::IgnoreEndMagic.into();
    let mut r = Recovered {
        was_complete: input.ends_with(mcap::MAGIC) && input.len() > 2 * mcap::MAGIC.len(),
        ..Recovered::default()
    };
    let opts = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .chunk_size(Some(4 * 1024 * 1024))
        .profile("")
        .library(format!(
            "gyrobench {} (recovered)",
            env!("CARGO_PKG_VERSION")
        ));
    let mut w = opts
        .create(BufWriter::new(File::create(out)?))
        .map_err(mcap_err)?;

    // The run metadata (top-level records, outside chunks).
    let records = LinearReader::new_with_options(input, lenient()).map_err(mcap_err)?;
    for rec in records {
        let Ok(rec) = rec else { break };
        if let mcap::records::Record::Metadata(m) = &rec {
            w.write_metadata(m).map_err(mcap_err)?;
        }
    }

    let stream = MessageStream::new_with_options(input, lenient()).map_err(mcap_err)?;
    for m in stream {
        let Ok(m) = m else { break };
        if m.channel.topic == topics::FRAMES
            && let Ok(v) = serde_json::from_slice::<serde_json::Value>(&m.data)
        {
            r.frames += v["counts"].as_array().map_or(0, |a| a.len() as u64);
        }
        w.write(&m).map_err(mcap_err)?;
        r.messages += 1;
    }
    w.finish().map_err(mcap_err)?;
    let kept = recovered_bytes(input);
    r.bytes_lost = (input.len() as u64).saturating_sub(kept);
    Ok(r)
}

/// Offset just past the last record that reads whole.
fn recovered_bytes(input: &[u8]) -> u64 {
    let magic = mcap::MAGIC.len();
    let mut at = magic;
    while at + 9 <= input.len() {
        let len = u64::from_le_bytes(input[at + 1..at + 9].try_into().unwrap_or([0; 8]));
        let end = (at as u64).saturating_add(9).saturating_add(len);
        if end > input.len() as u64 {
            break;
        }
        at = end as usize;
    }
    at as u64
}
