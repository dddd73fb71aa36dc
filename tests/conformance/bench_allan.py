"""Side-by-side: gyrobench's overlapping ADEV against allantools `oadev`.

Same data (a seeded gyro-like rate series: white noise, flicker-like
Gauss-Markov sum, random walk and a large Earth-rate offset), same octave
taus, one run on this machine. Checks that both agree to 1e-9 relative
and prints both times and the speed-up (best of REPEATS each).

    python tests/conformance/bench_allan.py [N] [REPEATS]

Needs `cargo build --release --example allan_bench` (done here) and the
Python packages of tests/conformance/requirements.txt.
"""

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import allantools
import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def series(n, tau0):
    rng = np.random.default_rng(42)
    white = rng.normal(0.0, 0.12 / np.sqrt(tau0), n)  # ARW 0.002 deg/sqrt(h)
    walk = np.cumsum(rng.normal(0.0, 1e-5, n))
    gm = np.zeros(n)
    a = np.exp(-tau0 / 300.0)
    e = rng.normal(0.0, 0.003 * np.sqrt(1 - a * a), n)
    # First-order filter without a Python loop.
    from scipy.signal import lfilter
    gm = lfilter([1.0], [1.0, -a], e)
    return 9.77 + white + walk + gm


def main():
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    tau0 = 0.0025
    rate = series(n, tau0)
    subprocess.run(
        ["cargo", "build", "--release", "--quiet", "--example", "allan_bench"],
        cwd=ROOT,
        check=True,
    )
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "rate.f64"
        rate.astype("<f8").tofile(data)
        out = subprocess.run(
            [str(ROOT / "target/release/examples/allan_bench"), str(data), str(tau0), str(repeats)],
            check=True,
            capture_output=True,
            text=True,
        )
    ours = json.loads(out.stdout)
    taus = np.array(ours["tau_s"])
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        t_ref, dev_ref, _, _ = allantools.oadev(rate, rate=1.0 / tau0, data_type="freq", taus=taus)
        best = min(best, time.perf_counter() - t0)
    dev = np.array(ours["adev"])
    if len(t_ref) != len(taus) or not np.allclose(t_ref, taus, rtol=1e-12):
        print(f"tau mismatch: {t_ref} vs {taus}")
        return 1
    rel = np.max(np.abs(dev / dev_ref - 1.0))
    print(
        json.dumps(
            {
                "samples": n,
                "taus": len(taus),
                "allantools_s": best,
                "gyrobench_s": ours["seconds"],
                "speedup": best / ours["seconds"],
                "max_relative_difference": rel,
            },
            indent=1,
        )
    )
    if rel > 1e-9:
        print(f"FAIL: gyrobench and allantools differ by {rel:.2e} relative (limit 1e-9)")
        return 1
    print(f"ok: agree to {rel:.1e}; gyrobench {best / ours['seconds']:.1f}x faster")
    return 0


if __name__ == "__main__":
    sys.exit(main())
