//! Times `results sync` on a tree of run directories: the first sync (every
//! log new to the store), then syncs of the unchanged tree, which must read
//! no log (`docs/results.md`, "Benchmark").
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example sync_bench -- target/release/gyrobench /tmp/sync-bench 1000
//! ```
//!
//! Arguments: the gyrobench binary, a working directory (kept between
//! calls: runs already there are not made again), and how many runs the
//! tree holds. Each run is a short procedure (two 60 s records) on the
//! embedded bench, recorded nowhere (`--db none`), so the store learns of
//! them only through the sync. Prints the time of each sync, the median of
//! five unchanged syncs, and what each sync said.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

const TINY: &str = r#"
[procedure]
name = "tiny"
description = "two 60 s records"
dut_type = "RL-16"
spec = "sync benchmark"

[[setup]]
action = "chamber"
set_c = 20.0
ramp_c_per_min = 1.0

[[main]]
action = "record"
label = "up"
duration_s = 60.0

[[main]]
action = "measure"
name = "bias_dph:up"
metric = "mean_bias"
records = ["up"]
low = -5.0
high = 5.0
unit = "deg/h"
"#;

fn sync(bin: &str, db: &Path, runs: &Path) -> Result<(f64, String), Box<dyn std::error::Error>> {
    let t0 = Instant::now();
    let out = Command::new(bin)
        .args(["results", "--db", &db.display().to_string(), "sync"])
        .arg(runs)
        .output()?;
    let secs = t0.elapsed().as_secs_f64();
    if !out.status.success() {
        return Err(format!("sync failed: {}", String::from_utf8_lossy(&out.stderr)).into());
    }
    Ok((secs, String::from_utf8_lossy(&out.stdout).trim().to_owned()))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(bin), Some(work), Some(n)) = (args.get(1), args.get(2), args.get(3)) else {
        return Err("usage: sync_bench GYROBENCH WORK_DIR RUNS".into());
    };
    let n: usize = n.parse()?;
    let work = Path::new(work);
    let runs = work.join("runs");
    std::fs::create_dir_all(&runs)?;
    let procedure = work.join("tiny.toml");
    std::fs::write(&procedure, TINY)?;
    let t0 = Instant::now();
    let mut made = 0;
    for i in 0..n {
        let dir = runs.join(format!("run-{i:05}"));
        if dir.join("report.json").exists() {
            continue;
        }
        let _ = std::fs::remove_dir_all(&dir);
        let out = Command::new(bin)
            .arg("run")
            .arg(&procedure)
            .args(["--db", "none", "--seed", &(i + 1).to_string(), "--out"])
            .arg(&dir)
            .output()?;
        if !matches!(out.status.code(), Some(0 | 3)) {
            return Err(format!("run {i}: {}", String::from_utf8_lossy(&out.stderr)).into());
        }
        made += 1;
    }
    println!(
        "{n} run directories ({made} made now in {:.1} s)",
        t0.elapsed().as_secs_f64()
    );
    let db = work.join("results.sqlite");
    let _ = std::fs::remove_file(&db);
    let (first, said) = sync(bin, &db, &runs)?;
    println!("first sync (every log new): {first:.2} s\n  {said}");
    let mut again = Vec::new();
    let mut last = String::new();
    for _ in 0..5 {
        let (secs, said) = sync(bin, &db, &runs)?;
        again.push(secs);
        last = said;
    }
    again.sort_by(f64::total_cmp);
    println!(
        "sync of the unchanged tree: median {:.3} s of 5 (min {:.3}, max {:.3})\n  {last}",
        again[2], again[0], again[4]
    );
    Ok(())
}
