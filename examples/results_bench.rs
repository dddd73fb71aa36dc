//! Fills a results store with generated runs and times the questions a
//! lab asks of it (`docs/results.md`, "Benchmark").
//!
//! ```sh
//! cargo run --release --example results_bench -- /tmp/bench.sqlite 100000 30
//! cargo run --release --example results_bench -- postgres://gyrobench:gyrobench@127.0.0.1:54329/gyrobench 100000 30
//! ```
//!
//! Arguments: the store (a SQLite file or a postgres:// URL; it should be
//! empty or hold an earlier fill of this benchmark), the runs to add (2,000
//! units, 50 runs each at 100,000), and the measurements per run. Each run
//! is written as a live run writes itself: its start, then its end with
//! every measurement. Prints the fill time and, for each question, the
//! median of 7 timings, in milliseconds.

use std::time::Instant;

use gyrobench::procedure::Metric;
use gyrobench::protocol::frame::LinkStats;
use gyrobench::results::query::{Filter, MIN_CAPABILITY_N};
use gyrobench::results::record::PartEnd;
use gyrobench::results::{Location, Store};
use gyrobench::runlog::meta::RunMeta;
use gyrobench::sequencer::measure::{MeasureOutcome, Records};
use gyrobench::sequencer::{Outcome, RunResult};
use gyrobench_model::measurement::Measurement;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(db), Some(runs), Some(per)) = (args.get(1), args.get(2), args.get(3)) else {
        return Err("usage: results_bench STORE RUNS MEASUREMENTS_PER_RUN".into());
    };
    let runs: usize = runs.parse()?;
    let per: usize = per.parse()?;
    let mut store = Store::open(&Location::parse(db))?.ok_or("the store is `none`")?;
    let units = (runs / 50).max(1);
    let log = std::env::temp_dir().join("gyrobench-results-bench.mcap");
    std::fs::write(&log, b"a stand-in for a run's log")?;
    let have = store.list(&Filter {
        limit: Some(1),
        ..Filter::default()
    })?;
    let t0 = Instant::now();
    if have.is_empty() {
        fill(&mut store, &log, runs, units, per)?;
        println!(
            "filled {} with {runs} runs of {per} measurements in {:.1} s",
            store.name(),
            t0.elapsed().as_secs_f64()
        );
    } else {
        println!(
            "{} holds runs already: timing the questions only",
            store.name()
        );
    }
    let serial = format!("RL16-{:05}", units / 2);
    let mut time = |what: &str, f: &mut dyn FnMut(&mut Store) -> usize| {
        let mut ms: Vec<f64> = (0..7)
            .map(|_| {
                let t = Instant::now();
                let n = f(&mut store);
                assert!(n > 0, "{what}: nothing found");
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        println!("{what:<58} {:>8.1} ms", ms[3]);
    };
    time(
        &format!("unit {serial}: every run and measurement"),
        &mut |s| s.unit(&serial).map_or(0, |h| h.measurements.len()),
    );
    time("list: 50 newest failed acceptances", &mut |s| {
        s.list(&Filter {
            procedure: Some("acceptance".into()),
            outcome: Some(gyrobench::results::RunState::Fail),
            limit: Some(50),
            latest_only: true,
            ..Filter::default()
        })
        .map_or(0, |r| r.len())
    });
    time(&format!("list: runs of {serial} since June"), &mut |s| {
        s.list(&Filter {
            serial: Some(serial.clone()),
            since: Some("2026-06-01".into()),
            limit: Some(50),
            latest_only: true,
            ..Filter::default()
        })
        .map_or(0, |r| r.len() + 1)
    });
    time(
        "trend compensated_drift_pp_dph across all units",
        &mut |s| {
            s.trend(
                "compensated_drift_pp_dph",
                &Filter::default(),
                MIN_CAPABILITY_N,
            )
            .map_or(0, |t| t.count as usize)
        },
    );
    time(
        "trend compensated_drift_pp_dph, acceptance, since June",
        &mut |s| {
            s.trend(
                "compensated_drift_pp_dph",
                &Filter {
                    procedure: Some("acceptance".into()),
                    since: Some("2026-06-01".into()),
                    ..Filter::default()
                },
                MIN_CAPABILITY_N,
            )
            .map_or(0, |t| t.count as usize)
        },
    );
    Ok(())
}

/// `runs` generated runs of `units` units, `per` measurements each,
/// written as a live run writes itself: its start, then its end.
fn fill(
    store: &mut Store,
    log: &std::path::Path,
    runs: usize,
    units: usize,
    per: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    for i in 0..runs {
        let unit = i % units;
        let day = i * 365 / runs.max(1);
        let started = format!(
            "2026-{:02}-{:02}T{:02}:00:00+00:00",
            1 + day / 31 % 12,
            1 + day % 28,
            i % 24
        );
        let procedure = ["acceptance", "smoke", "orientation"][i % 3];
        let meta = RunMeta {
            format: 2,
            run_id: format!("bench{i:08}"),
            procedure_toml: format!("[procedure]\nname = \"{procedure}\"\n"),
            procedure_path: format!("procedures/{procedure}.toml"),
            bench: format!("bench-{}", i % 8),
            station: format!("pc-{}", i % 8),
            dut_serial: format!("RL16-{unit:05}"),
            dut_type: "RL-16".into(),
            software_version: "bench".into(),
            start_time_utc: started.clone(),
            part_start_time_utc: started,
            part: 1,
            ..RunMeta::default()
        };
        let key = store.begin_part(&meta, log)?;
        let measurements: Vec<Measurement> = (0..per).map(|k| measurement(i, k)).collect();
        let outcome = match i % 100 {
            0..=94 => Outcome::Pass,
            95..=98 => Outcome::Fail,
            _ => Outcome::Error,
        };
        let result = RunResult {
            outcome,
            measurements,
            error: None,
            cleanup_completed: true,
            device_time_s: 40_000.0,
            frames: 16_000_000,
            records: Records::default(),
            bench_left: None,
            others: Vec::new(),
        };
        store.finish_part(
            &key,
            log,
            &PartEnd {
                result: &result,
                link: LinkStats::default(),
                ended_utc: meta.part_start_time_utc.clone(),
                slots: Vec::new(),
            },
        )?;
    }
    Ok(())
}

/// Measurement `k` of generated run `i`: the compensated drift first,
/// the rest numbered figures, every value inside or just outside 0.05.
fn measurement(i: usize, k: usize) -> Measurement {
    let name = if k == 0 {
        "compensated_drift_pp_dph".to_owned()
    } else {
        format!("figure_{k:02}")
    };
    let value = 0.03 + 0.01 * (((i * 7 + k * 13) % 100) as f64 / 50.0 - 1.0);
    Measurement {
        name,
        value: Some(value),
        unit: "deg/h".into(),
        low: Some(0.0),
        high: Some(0.05),
        outcome: if value <= 0.05 {
            MeasureOutcome::Pass
        } else {
            MeasureOutcome::Fail
        },
        step: format!("main.{k}"),
        metric: Metric::CompensatedDriftPp,
        averaging_s: 600.0,
        records: Vec::new(),
        note: String::new(),
        std_error: None,
        uncertainty: None,
        uncertainty_reason: None,
        guard_band: None,
        margin: None,
        margin_u: None,
        noise_floor: None,
        trace: None,
        band: None,
    }
}
