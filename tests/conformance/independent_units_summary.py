#!/usr/bin/env python3
"""What gyrobench diagnose made of the units independent_units.sh ran:
per case, the withheld effect named first, named at all, left
inconclusive with it first, or something else named; disturbances
outside the library reported; the thermal layer's held-out gap.

    python3 independent_units_summary.py OUTDIR [OUTDIR...]
"""
import json
import math
import os
import sys
from collections import defaultdict


def main():
    units = []
    for root in sys.argv[1:]:
        for name in sorted(os.listdir(root)):
            d = os.path.join(root, name)
            try:
                truth = json.load(open(os.path.join(d, "truth.json")))
                diag = json.load(open(os.path.join(d, "d", "diagnosis.json")))
            except (FileNotFoundError, NotADirectoryError):
                continue
            units.append((truth, diag))
    by = defaultdict(list)
    for t, d in units:
        by[t["case"]].append((t, d))
    print(f"{'case':24s} units  first  named  inconclusive  other named   outside reported")
    for case, rows in sorted(by.items()):
        first = named = undecided = outside = 0
        other = []
        for t, d in rows:
            withheld = t["withheld"]
            effects = [e["name"] for e in d["effects"]]
            inc = [c["name"] for c in (d.get("inconclusive") or {}).get("candidates", [])]
            first += bool(withheld) and bool(effects) and effects[0] in withheld
            named += bool(withheld) and all(w in effects for w in withheld)
            undecided += bool(withheld) and not effects and bool(inc) and inc[0] in withheld
            other += [e for e in effects if e not in withheld]
            outside += bool(d["unexplained"]["outside"])
        print(f"{case:24s} {len(rows):5d} {first:6d} {named:6d} {undecided:13d}  "
              f"{len(other):3d} {','.join(sorted(set(other))):20s} {outside:3d}")
    gaps = sorted(d["layers"]["thermal"]["gap_c"] for _, d in units)
    n = len(gaps)
    if n:
        within = sum(g <= 0.05 for g in gaps)
        misfit = sum(d["layers"]["thermal"].get("form_misfit") is not None for _, d in units)
        print(f"thermal layer held out: within 0.05 degC {within}/{n}, median {gaps[n // 2]:.4f}, "
              f"90 % {gaps[int(0.9 * n)]:.4f}, max {gaps[-1]:.4f} degC; network form misses in {misfit}")
        bad = [t["seed"] for t, d in units if not all(
            math.isfinite(v) for v in (d["layers"]["thermal"].get("fitted") or {}).values()
            if isinstance(v, float))]
        print(f"fitted networks with a non-finite value: {bad or 'none'}")


if __name__ == "__main__":
    main()
