//! What a part's log says its stored rows hold: the `runs` columns its
//! `run` metadata gives (written when the part begins), those its end
//! gives (written when it ends), and each unit's `run_units` columns. The
//! store writes its rows from these lists, one place for each column.

use std::path::Path;

use super::sql::Value;
use crate::coeffs::CoeffsUsed;
use crate::protocol::frame::LinkStats;
use crate::runlog::meta::RunMeta;
use crate::runlog::replay::{Replayed, replay, replay_unit};
use crate::sequencer::{RunResult, UnitResult};

/// A column and its value.
pub type Column = (&'static str, Value);

/// The `runs` columns a part's `run` metadata gives: the part `key` of
/// the run `run`.
pub fn begun(meta: &RunMeta, key: &str, run: &str) -> Vec<Column> {
    let parent = (meta.part > 1).then(|| format!("{run}.{}", meta.part - 1));
    let overdue: Vec<&str> = meta
        .instruments
        .iter()
        .filter(|i| i.calibration_overdue)
        .map(|i| i.role.as_str())
        .collect();
    vec![
        ("id", key.into()),
        ("run_id", run.into()),
        ("part", i64::from(meta.part).into()),
        ("parent_id", parent.into()),
        (
            "procedure_name",
            crate::procedure::raw_name(&meta.procedure_toml)
                .unwrap_or_default()
                .into(),
        ),
        (
            "procedure_sha256",
            crate::fsutil::sha256_text(&meta.procedure_toml).into(),
        ),
        ("procedure_path", meta.procedure_path.clone().into()),
        ("bench", meta.bench.clone().into()),
        ("station", meta.station.clone().into()),
        ("operator", meta.operator.clone().into()),
        ("seed", meta.seed.and_then(|s| i64::try_from(s).ok()).into()),
        ("software_version", meta.software_version.clone().into()),
        ("run_started_utc", meta.start_time_utc.clone().into()),
        ("started_utc", meta.part_start_time_utc.clone().into()),
        ("imported_from", meta.imported_from.clone().into()),
        ("bench_id", meta.bench_id.clone().into()),
        ("host", meta.host.clone().into()),
        ("software_revision", meta.software_revision.clone().into()),
        (
            "instruments",
            serde_json::to_string(&meta.instruments)
                .unwrap_or_default()
                .into(),
        ),
        (
            "calibration_overdue",
            (!overdue.is_empty()).then(|| overdue.join(",")).into(),
        ),
    ]
}

/// How the store names where a run's coefficients came from.
fn coeffs_source(s: crate::coeffs::CoeffsSource) -> &'static str {
    match s {
        crate::coeffs::CoeffsSource::Fitted => "fitted",
        crate::coeffs::CoeffsSource::File => "file",
        crate::coeffs::CoeffsSource::Store => "store",
    }
}

/// The `run_units` columns of the coefficients a unit used.
pub fn coefficients(c: &CoeffsUsed) -> Vec<Column> {
    let id = c.identity.as_ref();
    vec![
        ("coeffs_source", coeffs_source(c.source).into()),
        ("coeffs_serial", c.serial.clone().into()),
        ("coeffs_version", c.version.into()),
        ("coeffs_sha256", c.sha256.clone().into()),
        ("coeffs_override_reason", c.override_reason.clone().into()),
        ("coeffs_identity", id.map(|i| i.status.as_str()).into()),
        (
            "coeffs_claimed_version",
            id.and_then(|i| i.claimed_version).into(),
        ),
        ("coeffs_identity_note", id.map(|i| i.note.clone()).into()),
    ]
}

/// The `runs` columns how a part ended gives: `r` the run's result (a
/// batch's row carries its worst unit's outcome and error), `link` its
/// first unit's link figures over the whole run and `ended_utc` when it
/// ended (each left out when not known).
pub fn ended(r: &RunResult, link: Option<&LinkStats>, ended_utc: Option<&str>) -> Vec<Column> {
    let error = r.unit(r.worst_unit()).error;
    let left = r.bench_left.as_ref();
    let mut out: Vec<Column> = Vec::new();
    if let Some(t) = ended_utc {
        out.push(("ended_utc", t.into()));
    }
    out.extend([
        ("device_time_s", r.device_time_s.into()),
        ("frames", i64::try_from(r.frames).ok().into()),
        ("outcome", r.worst().as_str().into()),
        ("error_step", error.as_ref().map(|e| e.step.clone()).into()),
        (
            "error_device",
            error.as_ref().and_then(|e| e.device.clone()).into(),
        ),
        (
            "error_message",
            error.as_ref().map(|e| e.message.clone()).into(),
        ),
        ("cleanup_completed", r.cleanup_completed.into()),
        ("bench_left", left.map(|b| b.summary.clone()).into()),
        ("bench_left_verified", left.map(|b| b.verified).into()),
    ]);
    if let Some(l) = link {
        let n = |v: u64| Value::from(i64::try_from(v).ok());
        out.extend([
            ("link_frames", n(l.frames)),
            ("link_lost_frames", n(l.lost_frames)),
            ("link_crc_errors", n(l.crc_errors)),
            ("link_reconnects", n(l.reconnects)),
            ("link_longest_gap_ms", n(l.longest_gap_ms)),
        ]);
    }
    out
}

/// A part's log replayed whole, as a sync indexes it: the first unit, and
/// a batch's other units each from its own view of the log.
pub fn replay_all(log: &Path) -> Result<Replayed, String> {
    let mut r = replay(log, None).map_err(|e| e.to_string())?;
    for u in r.meta.units.iter().skip(1) {
        let o = replay_unit(log, None, Some(&u.serial)).map_err(|e| e.to_string())?;
        r.result.others.push(UnitResult {
            outcome: Some(o.result.outcome),
            measurements: o.result.measurements,
            error: o.result.error,
            frames: o.result.frames,
            records: Default::default(),
        });
    }
    Ok(r)
}
