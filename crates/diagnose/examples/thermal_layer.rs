//! The thermal layer alone on runs given as interchange CSV
//! (`docs/analysis.md`): what `gyrobench diagnose` reports under
//! `layers.thermal`, and how long the layer took, without the log reading
//! and the rate layer around it. A profiling and experimenting aid
//! (`docs/benchmarks.md`):
//!
//! ```sh
//! cargo run --release -p gyrobench-diagnose --example thermal_layer -- cycle.csv orient.csv
//! ```
//!
//! Every row is taken as recorded at rest (an interchange CSV has no
//! table rates), its step label as its record; the site is irrelevant to
//! the thermal layer, so the twin's is used.

use std::time::Instant;

use gyrobench_analysis::series::Interval;
use gyrobench_diagnose::data::{RunData, Sample};
use gyrobench_diagnose::thermal;
use gyrobench_model::geometry::Orientation;
use gyrobench_twin::twin::TwinConfig;

/// One interchange CSV file as a run; an error names the file and line.
fn read_run(path: &str) -> Result<RunData, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut samples = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| -> Result<f64, String> {
            f.get(i)
                .and_then(|v| v.trim().parse().ok())
                .ok_or_else(|| format!("{path}:{}: column {} is not a number", n + 1, i + 1))
        };
        let label = f.get(9).map(|s| s.trim().to_owned()).unwrap_or_default();
        samples.push(Sample {
            iv: Interval {
                time_s: num(0)?,
                rate_dph: num(1)?,
                t1_c: num(2)?,
                t2_c: num(3)?,
                tcase_c: num(4)?,
                chamber_c: num(5)?,
                ..Interval::default()
            },
            orientation: Orientation::new(num(6)?, num(7)?, num(8)?),
            record: label.clone(),
            step: label.into(),
            table_rate_body_dph: nalgebra::Vector3::zeros(),
        });
    }
    Ok(RunData {
        name: path.to_owned(),
        site: TwinConfig::default_rl16().site,
        samples,
    })
}

fn main() {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    if paths.is_empty() {
        eprintln!("usage: thermal_layer RUN.csv [RUN.csv ...]");
        std::process::exit(2);
    }
    let runs: Vec<RunData> = match paths.iter().map(|p| read_run(p)).collect() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let start = Instant::now();
    let layer = thermal::layer(&runs, None, false);
    let took = start.elapsed();
    match serde_json::to_string_pretty(&layer) {
        Ok(json) => println!("{json}"),
        Err(e) => eprintln!("error: {e}"),
    }
    eprintln!("thermal layer: {:.3} s", took.as_secs_f64());
}
