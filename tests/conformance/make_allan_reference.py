"""Reference Allan figures from allantools for gyrobench's unit tests.

Writes three seeded series of integer counts, fixtures/allan/<name>.txt
(gyro: white rate noise, flicker and a random walk; white_pm: the
difference of white noise, like quantization; random_walk: integrated
white noise), and fixtures/allan/reference.json: for each series and
octave tau, allantools' `oadev`,
the noise type from `autocorr_noise_id`, the Greenhall EDF from
`edf_greenhall` and the one-sigma interval from `confidence_interval`.
The rate in deg/h is counts * 0.1 at 1 Hz.

    python tests/conformance/make_allan_reference.py fixtures/allan
"""

import json
import sys
from pathlib import Path

import allantools
import numpy as np
from allantools import ci

LSB = 0.1
N = 20000


def series():
    rng = np.random.default_rng(20261122)
    white = rng.normal(0.0, 20.0, N)
    walk = np.cumsum(rng.normal(0.0, 0.05, N))
    # Flicker: a sum of first-order Gauss-Markov processes, one per octave.
    flicker = np.zeros(N)
    for k in range(12):
        tc = 2.0 ** k
        a = np.exp(-1.0 / tc)
        e = rng.normal(0.0, 0.6 * np.sqrt(1 - a * a), N)
        x = 0.0
        for i in range(N):
            x = a * x + e[i]
            flicker[i] += x
    return np.round(white + walk + flicker + 150.0).astype(np.int64)


def points(rate):
    n = len(rate)
    ms = [2 ** k for k in range(24) if 2 ** k <= n // 3]
    taus, devs, _, _ = allantools.oadev(rate, rate=1.0, data_type="freq", taus=[float(m) for m in ms])
    rows = []
    for m, tau, dev in zip(ms, taus, devs):
        row = {"m": m, "tau_s": float(tau), "oadev": float(dev)}
        if n // m >= 30:
            alpha = int(ci.autocorr_noise_id(rate, m, data_type="freq")[0])
            row["alpha"] = alpha
            if alpha + 4 > 1:  # Greenhall's EDF for the ADEV needs alpha > -3
                edf = float(ci.edf_greenhall(alpha=alpha, d=2, m=m, N=n + 1, overlapping=True, modified=False))
                lo, hi = ci.confidence_interval(dev, edf)
                row.update(edf=edf, lo=float(lo), hi=float(hi))
        rows.append(row)
    return rows


def main(out):
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(7)
    pm = rng.integers(-50, 50, N + 1)
    all_series = {
        "gyro": series(),
        "white_pm": np.diff(pm),
        "random_walk": np.cumsum(rng.integers(-3, 4, N)),
    }
    doc = {
        "made_by": "tests/conformance/make_allan_reference.py",
        "allantools": getattr(allantools, "__version__", ""),
        "lsb_dph": LSB,
        "tau0_s": 1.0,
        "series": {},
    }
    for name, counts in all_series.items():
        (out / f"{name}.txt").write_text("\n".join(str(int(c)) for c in counts) + "\n")
        doc["series"][name] = points(counts * LSB)
    (out / "reference.json").write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "fixtures/allan")
