#!/usr/bin/env bash
# The pages as a person sees them, in headless Chromium: report.html of a
# PASS and of a FAIL, the FAIL printed to A4 (page 1), diagnosis.html, the
# calibration page, a rate-transfer report and the station (one unit, and a batch). Writes docs/img/*.png from a fresh build; run from
# the repository root:
#
#   docs/screenshots.sh
#
# Needs: chromium and pdftoppm (Debian: apt-get install chromium poppler-utils);
# for the station, chromium-driver and .venv with selenium (.ci/run makes it).
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
$gb run procedures/thermal_cycle.toml --out "$work/cycle2" --db none --seed 2 >/dev/null 2>&1 || [ $? -eq 4 ]
$gb diagnose "$work/fail/run.mcap" --out "$work/diag" >/dev/null 2>&1
$gb calibrate "$work/pass/run.mcap" "$work/cycle2/run.mcap" -o "$work/unit.toml" >/dev/null 2>&1
# A unit with some scale-factor curvature and asymmetry on the rate table.
$gb twin default-config |
    sed '/^\[rate_response\]/,/^$/{s/^nonlinearity_ppm = .*/nonlinearity_ppm = 30.0/;s/^asymmetry_ppm = .*/asymmetry_ppm = 4.0/}' \
        >"$work/rate.toml"
$gb run procedures/rate_transfer.toml --out "$work/rate" --db none --twin "$work/rate.toml" >/dev/null 2>&1 || [ $? -eq 3 ]

shot() { # page.html out.png height
    chromium --headless --no-sandbox --disable-gpu --hide-scrollbars \
        --window-size=1000,"$3" --screenshot="$2" "file://$1" 2>/dev/null
    echo "$2"
}
shot "$work/pass/report.html" "$img/report-pass.png" 1250
shot "$work/fail/report.html" "$img/report-fail.png" 1250
shot "$work/diag/diagnosis.html" "$img/diagnosis.png" 1100
shot "$work/unit.calibration.html" "$img/calibration.png" 1000
shot "$work/rate/report.html" "$img/report-rate.png" 1150
chromium --headless --no-sandbox --disable-gpu --no-pdf-header-footer \
    --print-to-pdf="$work/fail.pdf" "file://$work/fail/report.html" 2>/dev/null
pdftoppm -r 70 -png -f 1 -l 1 -singlefile "$work/fail.pdf" "$img/report-fail-a4"
echo "$img/report-fail-a4.png"

# The station during an acceptance at 2000x, driven as an operator would:
# 16 s in, the thermal cycle done and the nine positions under way (the
# drift chart leaves their slews out).
if [ -x .venv/bin/python ] && .venv/bin/python -c "import selenium" 2>/dev/null; then
    $gb station --listen 127.0.0.1:0 --live 127.0.0.1:0 --db none --runs "$work/station" --speed 2000 >"$work/station.out" 2>/dev/null &
    station=$!
    sleep 1.5
    url=$(head -1 "$work/station.out" | cut -d' ' -f2)
    .venv/bin/python - "$url" "$img/station.png" <<'PY'
import sys, time
from selenium import webdriver
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
o = webdriver.ChromeOptions()
for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,1150"):
    o.add_argument(a)
import shutil
d = webdriver.Chrome(options=o, service=webdriver.ChromeService(executable_path=shutil.which("chromedriver")))
d.get(sys.argv[1]); time.sleep(1)
d.find_element(By.CSS_SELECTOR, "#procedure option[value='acceptance.toml']").click()
d.find_element(By.ID, "serial").send_keys("RL16-0042", Keys.ENTER)
d.switch_to.active_element.send_keys("ann", Keys.ENTER)
d.find_element(By.ID, "start").click()
time.sleep(16)
d.save_screenshot(sys.argv[2]); d.quit()
PY
    kill -TERM "$station"; wait "$station" || true
    echo "$img/station.png"

    # A batch of four on the quad bench, mid-run: a tile per unit.
    $gb station --bench fixtures/bench/quad.toml --listen 127.0.0.1:0 --live 127.0.0.1:0 --db none \
        --runs "$work/station-batch" --speed 2000 >"$work/station-batch.out" 2>/dev/null &
    station=$!
    sleep 1.5
    url=$(head -1 "$work/station-batch.out" | cut -d' ' -f2)
    .venv/bin/python - "$url" "$img/station-batch.png" <<'PY'
import sys, time, shutil
from selenium import webdriver
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
o = webdriver.ChromeOptions()
for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000"):
    o.add_argument(a)
d = webdriver.Chrome(options=o, service=webdriver.ChromeService(executable_path=shutil.which("chromedriver")))
d.get(sys.argv[1]); time.sleep(1)
d.find_element(By.CSS_SELECTOR, "#procedure option[value='acceptance.toml']").click()
for slot, serial in zip("ABCD", ["RL16-0101", "RL16-0102", "RL16-0103", "RL16-0104"]):
    d.find_element(By.ID, f"serial-{slot}").send_keys(serial, Keys.ENTER)
d.switch_to.active_element.send_keys("ann", Keys.ENTER)
d.find_element(By.ID, "start").click()
time.sleep(9)
d.save_screenshot(sys.argv[2]); d.quit()
PY
    kill -TERM "$station"; wait "$station" || true
    echo "$img/station-batch.png"
else
    echo "screenshots: no .venv with selenium: the station was not shot" >&2
fi
