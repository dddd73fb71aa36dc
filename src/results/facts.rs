//! What a part's log says its stored rows hold. The `runs` columns its
//! `run` metadata gives (written when the part begins), those its end
//! gives (written when it ends), each unit's `run_units` columns, and its
//! figures. The store writes its rows from these lists and `results
//! verify` compares the rows against them, so what is written and what is
//! checked cannot drift apart.

use std::path::Path;

use super::sql::Value;
use crate::coeffs::CoeffsUsed;
use crate::protocol::frame::LinkStats;
use crate::runlog::meta::{ResultMeasurement, ResultMeta, RunMeta};
use crate::runlog::replay::{ReplayError, Replayed, replay, replay_unit};
use crate::sequencer::{RunResult, UnitResult};

/// The kind of bench a run ran on (`runs.bench_kind`; `results trend
/// --bench-kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BenchKind {
    /// The simulated bench inside gyrobench.
    Embedded,
    /// A bench of devices that identified themselves as gyrobench's
    /// simulators (`sim serve`).
    Simulated,
    /// Any other bench of devices.
    Hardware,
    /// Another lab's file, imported.
    Imported,
}

impl BenchKind {
    /// The kind of the bench `meta`'s run ran on: the instruments'
    /// identities as they answered tell a served simulator from hardware.
    pub fn of(meta: &RunMeta) -> Self {
        if meta.imported_from.is_some() {
            Self::Imported
        } else if meta.is_embedded() {
            Self::Embedded
        } else if meta
            .instruments
            .iter()
            .filter_map(|i| i.identity.as_ref())
            .any(crate::sim::identity::is_simulator)
        {
            Self::Simulated
        } else {
            Self::Hardware
        }
    }

    /// As stored.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Embedded => "embedded",
            Self::Simulated => "simulated",
            Self::Hardware => "hardware",
            Self::Imported => "imported",
        }
    }
}

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
    // The rule the run was judged by, from the procedure it logged; none
    // for a log written before decision rules (judged by its limits).
    let rule = (meta.format >= crate::runlog::schema::FORMAT_JUDGED)
        .then(|| {
            crate::procedure::raw_rule(
                &meta.procedure_toml,
                meta.format < crate::runlog::schema::FORMAT_JUDGED,
            )
        })
        .flatten();
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
        ("bench_kind", BenchKind::of(meta).as_str().into()),
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
        ("decision_rule", rule.map(|r| r.name().to_owned()).into()),
        (
            "guard_band_u",
            match rule {
                Some(crate::procedure::DecisionRule::Guarded { guard_band_u }) => {
                    Some(guard_band_u)
                }
                _ => None,
            }
            .into(),
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
pub fn replay_all(log: &Path) -> Result<Replayed, ReplayError> {
    let mut r = replay(log, None)?;
    for u in r.meta.units.iter().skip(1) {
        let o = replay_unit(log, None, Some(&u.serial))?;
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

/// Every unit's figures of `r` with its slot, in unit order.
fn figures_of(meta: &RunMeta, r: &RunResult) -> Vec<(String, ResultMeasurement)> {
    (0..r.units())
        .flat_map(|k| {
            let slot = meta.units.get(k).map_or(String::new(), |u| u.slot.clone());
            r.unit(k)
                .measurements
                .iter()
                .map(|m| (slot.clone(), ResultMeasurement::from(m)))
                .collect::<Vec<_>>()
        })
        .collect()
}

/// What a part's log holds that its stored rows must say.
#[derive(Debug)]
pub struct LogFacts {
    /// Its `run` metadata.
    pub meta: RunMeta,
    /// How it ended: the run's verdict, error, device time, frames,
    /// cleanup and bench left, each unit's (its figures are `figures`).
    pub result: RunResult,
    /// The first unit's link figures over the run (the report's), when the
    /// log holds them.
    pub link: Option<LinkStats>,
    /// When the part ended, when the log states it.
    pub ended_utc: Option<String>,
    /// Every unit's figures with its slot, in unit order.
    pub figures: Vec<(String, ResultMeasurement)>,
}

impl LogFacts {
    /// Read them from `log`: its `result` records (a batch's other units'
    /// `result/NAME`), or, for a log without one (a killed run, as a sync
    /// completed it) or with `replay`, its figures and ending recomputed
    /// from its frames.
    pub fn read(log: &Path, replay: bool) -> Result<Self, FactsError> {
        if replay {
            return Ok(Self::replayed(replay_all(log)?));
        }
        let read = Records::read(log)?;
        let Some(meta) = read.meta else {
            return Err(FactsError::NoRunMeta);
        };
        let Some(first) = read.result else {
            // A killed run's log: what a sync made of it.
            return Ok(Self::replayed(replay_all(log)?));
        };
        let (result, figures) = from_records(&meta, &first, &read.others)?;
        Ok(Self {
            meta,
            result,
            link: read.link,
            ended_utc: first.end_time_utc,
            figures,
        })
    }

    /// The facts of a replay (the figures, the verdict and the link
    /// figures recomputed from the frames, as a sync stores them).
    fn replayed(r: Replayed) -> Self {
        Self {
            figures: figures_of(&r.meta, &r.result),
            link: Some(r.link),
            ended_utc: r.end_time_utc,
            result: r.result,
            meta: r.meta,
        }
    }
}

/// The metadata and report a log holds, read in one pass.
#[derive(Default)]
struct Records {
    meta: Option<RunMeta>,
    result: Option<ResultMeta>,
    /// A batch's other units' `result/NAME`, by slot name.
    others: Vec<(String, ResultMeta)>,
    link: Option<LinkStats>,
}

/// Why a log's facts could not be read.
#[derive(Debug, thiserror::Error)]
pub enum FactsError {
    /// The log cannot be read.
    #[error(transparent)]
    Read(#[from] crate::runlog::ReadError),
    /// A metadata record does not parse (the first one that does not).
    #[error(transparent)]
    Meta(#[from] crate::runlog::meta::MetaError),
    /// No `run` metadata.
    #[error("the log holds no `run` metadata")]
    NoRunMeta,
    /// A batch's unit without its `result/SLOT` record.
    #[error("the log holds no `result/{slot}` record for unit {serial} of its batch")]
    NoUnitResult {
        /// The unit's slot.
        slot: String,
        /// Its serial.
        serial: String,
    },
    /// Its figures could not be replayed from its frames.
    #[error(transparent)]
    Replay(#[from] crate::runlog::replay::ReplayError),
}

impl Records {
    fn read(log: &Path) -> Result<Self, FactsError> {
        use crate::runlog::schema::{REPORT_ATTACHMENT, RESULT_META, RUN_META};
        let mut out = Self::default();
        // A record that does not parse is said, never skipped.
        let mut bad: Option<crate::runlog::meta::MetaError> = None;
        let mut keep = |what: Result<ResultMeta, crate::runlog::meta::MetaError>| match what {
            Ok(r) => Some(r),
            Err(e) => {
                bad.get_or_insert(e);
                None
            }
        };
        let mut meta_error = None;
        crate::runlog::read(log, |item| {
            match item {
                crate::runlog::Item::Meta { name, entries }
                    if name == RUN_META && out.meta.is_none() =>
                {
                    match RunMeta::from_entries(entries) {
                        Ok(m) => out.meta = Some(m),
                        Err(e) => meta_error = Some(e),
                    }
                }
                crate::runlog::Item::Meta { name, entries } if name == RESULT_META => {
                    out.result = keep(ResultMeta::from_entries(entries));
                }
                crate::runlog::Item::Meta { name, entries } => {
                    if let Some(slot) = name
                        .strip_prefix(RESULT_META)
                        .and_then(|r| r.strip_prefix('/'))
                        && let Some(r) = keep(ResultMeta::from_entries(entries))
                    {
                        out.others.push((slot.to_owned(), r));
                    }
                }
                crate::runlog::Item::Attachment { name, data, .. } if name == REPORT_ATTACHMENT => {
                    out.link = serde_json::from_slice::<serde_json::Value>(data)
                        .ok()
                        .and_then(|j| serde_json::from_value(j.get("link")?.clone()).ok());
                }
                _ => {}
            }
            std::ops::ControlFlow::Continue(())
        })?;
        if let Some(e) = meta_error.or(bad) {
            return Err(e.into());
        }
        Ok(out)
    }
}

/// The run's ending and figures as its `result` records give them (the
/// first unit's, then a batch's others' by slot).
fn from_records(
    meta: &RunMeta,
    first: &ResultMeta,
    others: &[(String, ResultMeta)],
) -> Result<(RunResult, Vec<(String, ResultMeasurement)>), FactsError> {
    let slot0 = meta.units.first().map_or(String::new(), |u| u.slot.clone());
    let mut figures: Vec<(String, ResultMeasurement)> = first
        .measurements
        .iter()
        .map(|m| (slot0.clone(), m.clone()))
        .collect();
    let mut units = Vec::new();
    for u in meta.units.iter().skip(1) {
        let Some((_, r)) = others.iter().find(|(slot, _)| *slot == u.slot) else {
            return Err(FactsError::NoUnitResult {
                slot: u.slot.clone(),
                serial: u.serial.clone(),
            });
        };
        figures.extend(r.measurements.iter().map(|m| (u.slot.clone(), m.clone())));
        units.push(UnitResult {
            outcome: Some(r.outcome),
            measurements: Vec::new(),
            error: r.error.clone(),
            frames: r.frames,
            records: Default::default(),
        });
    }
    let result = RunResult {
        outcome: first.outcome,
        measurements: Vec::new(),
        error: first.error.clone(),
        cleanup_completed: first.cleanup_completed,
        // A result record of the first format states none: not a number,
        // which the store keeps as null.
        device_time_s: first.device_time_s.unwrap_or(f64::NAN),
        frames: first.frames,
        records: Default::default(),
        bench_left: first.bench_left.clone(),
        others: units,
    };
    Ok((result, figures))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::Instrument;

    fn table(reply: &str) -> Instrument {
        Instrument {
            role: "table".into(),
            spec: "tcp://127.0.0.1:5003".into(),
            identity: Some(crate::protocol::acl::parse_identity(reply)),
            identity_error: None,
            calibration_due: None,
            calibration_overdue: false,
        }
    }

    /// The bench's kind from what the run logged: its name, an import,
    /// and its instruments' answers (a served simulator names itself).
    #[test]
    fn a_bench_is_classed_by_its_name_its_import_and_its_instruments() {
        let embedded = RunMeta {
            bench: "embedded".into(),
            ..RunMeta::default()
        };
        assert_eq!(BenchKind::of(&embedded), BenchKind::Embedded);
        let mut served = RunMeta {
            bench: "fixtures/bench/sim-serve.toml".into(),
            ..RunMeta::default()
        };
        served.instruments = vec![table(crate::sim::identity::ACL_IDN)];
        assert_eq!(BenchKind::of(&served), BenchKind::Simulated);
        let mut real = served.clone();
        real.instruments = vec![table("ACUTRONIC,AC2247,10234,4.2.1")];
        assert_eq!(BenchKind::of(&real), BenchKind::Hardware);
        real.instruments.clear();
        assert_eq!(
            BenchKind::of(&real),
            BenchKind::Hardware,
            "silent: not ours"
        );
        let imported = RunMeta {
            imported_from: Some("lab.csv".into()),
            ..served
        };
        assert_eq!(BenchKind::of(&imported), BenchKind::Imported);
    }
}
