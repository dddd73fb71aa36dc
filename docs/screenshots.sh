#!/usr/bin/env bash
# The pages as a person sees them, in headless Chromium: report.html of a
# PASS and of a FAIL, the FAIL printed to A4 (page 1), diagnosis.html and
# the calibration page. Writes docs/img/*.png from a fresh build; run from
# the repository root:
#
#   docs/screenshots.sh
#
# Needs: chromium and pdftoppm (Debian: apt-get install chromium poppler-utils).
set -euo pipefail

cd "$(dirname "$0")/.."
for tool in chromium pdftoppm; do
    command -v "$tool" >/dev/null || { echo "screenshots: $tool is not installed" >&2; exit 1; }
done
cargo build --release --quiet
gb=target/release/gyrobench
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
img=docs/img
mkdir -p "$img"

# A unit whose thermal hysteresis the model cannot compensate: it fails.
$gb twin default-config |
    sed '/^\[effects.hysteresis\]/,/^$/{s/^enabled = false/enabled = true/;s/^amplitude_dph = .*/amplitude_dph = 0.1/}' \
        >"$work/hysteresis.toml"
$gb run procedures/acceptance.toml --out "$work/pass" --db none >/dev/null 2>&1
$gb run procedures/acceptance.toml --out "$work/fail" --db none --dut RL16-0042 \
    --twin "$work/hysteresis.toml" >/dev/null 2>&1 || [ $? -eq 3 ]
$gb run procedures/thermal_cycle.toml --out "$work/cycle2" --db none --seed 2 >/dev/null 2>&1
$gb diagnose "$work/fail/run.mcap" --out "$work/diag" >/dev/null 2>&1
$gb calibrate "$work/pass/run.mcap" "$work/cycle2/run.mcap" -o "$work/unit.toml" >/dev/null 2>&1

shot() { # page.html out.png height
    chromium --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --window-size=1000,"$3" --screenshot="$2" "file://$1" 2>/dev/null
    echo "$2"
}
shot "$work/pass/report.html" "$img/report-pass.png" 1250
shot "$work/fail/report.html" "$img/report-fail.png" 1250
shot "$work/diag/diagnosis.html" "$img/diagnosis.png" 1100
shot "$work/unit.calibration.html" "$img/calibration.png" 1000
chromium --headless --no-sandbox --disable-gpu --no-pdf-header-footer \
    --print-to-pdf="$work/fail.pdf" "file://$work/fail/report.html" 2>/dev/null
pdftoppm -r 70 -png -f 1 -l 1 -singlefile "$work/fail.pdf" "$img/report-fail-a4"
echo "$img/report-fail-a4.png"
