//! The fault-and-resume sweep of a procedure (default: the shipped
//! acceptance) on the embedded bench at full speed: interrupted at every
//! step boundary and mid-step, by each fault kind, and resumed; every
//! resumed run checked (`tests/it/sweep.rs`). Prints the table
//! `docs/procedures.md` shows and exits non-zero on any problem. A third
//! argument N plays each fault at every Nth of its points only (CI's
//! shorter sweep; the default, 1, is the whole sweep).
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example resume_sweep -- target/release/gyrobench procedures/acceptance.toml
//! cargo run --release --example resume_sweep -- target/release/gyrobench procedures/acceptance.toml 3
//! ```

#![expect(
    clippy::expect_used,
    reason = "a sweep that cannot run should fail loudly"
)]

#[path = "../tests/it/http.rs"]
mod http;
#[path = "../tests/it/sweep.rs"]
mod sweep;

fn main() -> std::process::ExitCode {
    let mut args = std::env::args().skip(1);
    let bin = args
        .next()
        .unwrap_or_else(|| "target/release/gyrobench".into());
    let procedure = args
        .next()
        .unwrap_or_else(|| "procedures/acceptance.toml".into());
    let every: usize = match args.next().map(|a| a.parse::<usize>()) {
        None => 1,
        Some(Ok(n)) if n >= 1 => n,
        Some(_) => {
            eprintln!("resume_sweep: the third argument is a whole number >= 1 (every Nth point)");
            return std::process::ExitCode::from(2);
        }
    };
    let dir = std::env::temp_dir().join(format!("gyrobench-resume-sweep-{}", std::process::id()));
    let jobs = std::thread::available_parallelism().map_or(2, usize::from);
    let sweep = sweep::Sweep {
        bin: bin.into(),
        procedure: procedure.clone().into(),
        dir: dir.clone(),
        seeds: (1..=16).collect(),
        faults: vec![
            ("process-kill".into(), every),
            ("chamber-alarm".into(), 3 * every),
            ("table-interlock".into(), 5 * every),
            ("gyro-silent".into(), 5 * every),
            ("disk-full".into(), 5 * every),
            ("sighup".into(), 5 * every),
            ("sigquit".into(), 10 * every),
            ("station-sighup".into(), 10 * every),
            ("station-sigquit".into(), 10 * every),
        ],
        jobs,
    };
    let started = std::time::Instant::now();
    let (rows, totals) = sweep.run();
    println!("{}", sweep::render_rows(&rows));
    println!("{}", sweep::render(&rows, &totals));
    println!(
        "{procedure}: {} interruptions in {:.0} s on {jobs} cores",
        totals.runs,
        started.elapsed().as_secs_f64()
    );
    let bad = totals.lost
        + totals.overwritten
        + totals.resumes_failed
        + totals.bench_unsafe
        + totals.figures_outside
        + totals.retaken_outside;
    if bad == 0 {
        let _removed = std::fs::remove_dir_all(&dir);
        std::process::ExitCode::SUCCESS
    } else {
        eprintln!("runs kept in {}", dir.display());
        std::process::ExitCode::FAILURE
    }
}
