//! Times gyrobench's overlapping Allan deviation on a raw series, for the
//! side-by-side benchmark against allantools
//! (`tests/conformance/bench_allan.py` runs both on the same data).
//!
//! `cargo run --release --example allan_bench -- DATA.f64 TAU0_S [REPEATS]`
//! reads little-endian f64 rates and prints JSON: the octave taus, the
//! deviations and the best wall time of the ADEV computation alone.

use gyrobench::analysis::allan::{oadev, octave_factors};
use gyrobench::clock::time_it;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(path), Some(tau0)) = (args.get(1), args.get(2)) else {
        return Err("usage: allan_bench DATA.f64 TAU0_S [REPEATS]".into());
    };
    let tau0: f64 = tau0.parse()?;
    let repeats: usize = args.get(3).map_or(Ok(3), |r| r.parse())?;
    let bytes = std::fs::read(path)?;
    let rate: Vec<f64> = bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect();
    let factors = octave_factors(rate.len());
    let mut best = f64::INFINITY;
    let mut devs = Vec::new();
    for _ in 0..repeats.max(1) {
        let (d, secs) = time_it(|| oadev(&rate, tau0, &factors));
        best = best.min(secs);
        devs = d;
    }
    let out = serde_json::json!({
        "samples": rate.len(),
        "tau_s": devs.iter().map(|d| d.0).collect::<Vec<_>>(),
        "adev": devs.iter().map(|d| d.1).collect::<Vec<_>>(),
        "seconds": best,
    });
    println!("{out}");
    Ok(())
}
