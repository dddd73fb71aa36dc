"""How long a sample takes from the station to the page's chart.

    station_latency.py URL [SECONDS]

Starts the acceptance on the station at URL (a station serving at
`--speed 1`), then for SECONDS (default 60) records, for every chart update
of a real headless Chromium, the time from the newest sample's arrival at
the station to the page having drawn it (the page keeps it in
`window.lastLatencyMs`). Prints the median, 95th percentile and maximum.
"""

import shutil
import statistics
import sys
import time

from selenium import webdriver
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys

opts = webdriver.ChromeOptions()
for a in ("--headless=new", "--no-sandbox", "--disable-gpu"):
    opts.add_argument(a)
d = webdriver.Chrome(
    options=opts, service=webdriver.ChromeService(executable_path=shutil.which("chromedriver"))
)
try:
    d.get(sys.argv[1])
    time.sleep(1)
    d.find_element(By.CSS_SELECTOR, "#procedure option[value='acceptance.toml']").click()
    d.find_element(By.ID, "serial").send_keys("RL16-0042", Keys.ENTER)
    d.find_element(By.ID, "start").click()
    time.sleep(3)
    d.execute_script(
        "window.lat = []; setInterval(() => { if (window.lastLatencyMs !== undefined) "
        "{ window.lat.push(window.lastLatencyMs); window.lastLatencyMs = undefined; } }, 20);"
    )
    time.sleep(float(sys.argv[2]) if len(sys.argv) > 2 else 60.0)
    lat = sorted(d.execute_script("return window.lat"))
finally:
    d.quit()
if not lat:
    sys.exit("no chart update seen")
print(
    f"{len(lat)} chart updates: latency median {statistics.median(lat):.0f} ms, "
    f"95th {lat[max(0, int(0.95 * len(lat)) - 1)]:.0f} ms, max {lat[-1]:.0f} ms"
)
