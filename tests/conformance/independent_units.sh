#!/usr/bin/env bash
# Diagnose units made apart from the twin (independent_units.py) through the
# path a lab's runs take: interchange CSV -> gyrobench import -> diagnose.
#   tests/conformance/independent_units.sh GYROBENCH PYTHON OUTDIR FIRST_SEED UNITS [generator args]
# PYTHON needs numpy (the CI virtualenv has it). Cases cycle through
# null, the five effects, two pairs, a bias jump and a sine; each unit's
# directory keeps truth.json and d/diagnosis.json (the logs are removed).
# Then: PYTHON tests/conformance/independent_units_summary.py OUTDIR
set -euo pipefail
bin=$1; py=$2; root=$3; first=$4; n=$5; shift 5
here=$(cd "$(dirname "$0")" && pwd)
cases=(null hysteresis thermal_lag g_sensitivity magnetic_sensitivity axis_misalignment pair_g_hyst pair_mag_lag step sine)
mkdir -p "$root"
for ((i = 0; i < n; i++)); do
    seed=$((first + i))
    case=${ONLY_CASE:-${cases[$((i % ${#cases[@]}))]}}
    d="$root/$(printf %03d "$i")_${case}_s$seed"
    "$py" "$here/independent_units.py" --seed "$seed" --case "$case" --out "$d" "$@"
    for run in cycle orient; do
        "$bin" import "$d/$run.csv" --site "$d/site.toml" --dut "IND-$seed" -o "$d/$run.mcap" --db none > /dev/null
    done
    start=$(date +%s%N)
    "$bin" diagnose "$d/cycle.mcap" "$d/orient.mcap" --out "$d/d" > "$d/diagnose.out"
    echo "$((($(date +%s%N) - start) / 1000000)) ms" > "$d/wall"
    rm -f "$d"/*.mcap
    echo "$d: $(head -c 160 "$d/diagnose.out")"
done
