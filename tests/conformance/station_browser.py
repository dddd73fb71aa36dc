"""The station page as an operator uses it, in a real headless Chromium
driven over WebDriver (selenium, Debian's chromium-driver).

    station_browser.py URL [CHROMEDRIVER]

URL is the one `gyrobench station` prints (with its token). Runs the smoke
procedure: types the serial and the operator (Enter, as a barcode scanner
sends), ticks the checklist, starts, sees the steps advance and the prompt,
reloads mid-run (the same state comes back), opens a second browser (it sees
the same run), answers the prompt, sees PASS and the report; then starts
again and aborts at the prompt: cleanup runs and the verdict is ABORTED.
Exits non-zero with the step that failed.
"""

import sys
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support import expected_conditions as ec
from selenium.webdriver.support.ui import WebDriverWait


def browser(driver_path):
    opts = webdriver.ChromeOptions()
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000"):
        opts.add_argument(a)
    service = Service(executable_path=driver_path) if driver_path else Service()
    return webdriver.Chrome(options=opts, service=service)


def wait(d, what, cond, timeout=60):
    try:
        return WebDriverWait(d, timeout).until(cond)
    except Exception as e:  # noqa: BLE001 - say which step failed
        sys.exit(f"station page: {what}: not seen within {timeout} s ({type(e).__name__})")


def text_of(d, css):
    return d.find_element(By.CSS_SELECTOR, css).text


def start_smoke(d, serial):
    wait(d, "procedures listed", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#procedure option")) > 0)
    d.find_element(By.CSS_SELECTOR, "#procedure option[value='smoke.toml']").click()
    s = d.find_element(By.ID, "serial")
    s.clear()
    s.send_keys(serial, Keys.ENTER)
    wait(d, "Enter moves to the operator field", lambda d: d.switch_to.active_element.get_attribute("id") == "operator")
    d.switch_to.active_element.send_keys("ann", Keys.ENTER)
    for box in d.find_elements(By.CSS_SELECTOR, "#checklist input[type=checkbox]"):
        box.click()
    d.find_element(By.ID, "start").click()


def main():
    url = sys.argv[1]
    driver_path = sys.argv[2] if len(sys.argv) > 2 else None
    a = browser(driver_path)
    b = browser(driver_path)
    try:
        a.get(url)
        # Refused with its reason: no serial.
        wait(a, "procedures listed", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#procedure option")) > 0)
        for box in a.find_elements(By.CSS_SELECTOR, "#checklist input[type=checkbox]"):
            box.click()
        a.find_element(By.ID, "start").click()
        wait(a, "start refused without a serial", lambda d: "serial" in text_of(d, "#refusal"))
        for box in a.find_elements(By.CSS_SELECTOR, "#checklist input[type=checkbox]"):
            box.click()

        start_smoke(a, "RL16-0042")
        wait(a, "the run's steps", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#steps li")) >= 5)
        wait(a, "the prompt", ec.visibility_of_element_located((By.ID, "prompt")))
        assert "connector" in text_of(a, "#prompt-text"), text_of(a, "#prompt-text")
        steps_before = text_of(a, "#steps li.current")

        # Reload mid-run: the same state comes back.
        a.refresh()
        wait(a, "the prompt after a reload", ec.visibility_of_element_located((By.ID, "prompt")))
        assert text_of(a, "#steps li.current") == steps_before, "another step after the reload"
        assert "RL16-0042" in text_of(a, "#run-title"), text_of(a, "#run-title")

        # A second browser sees the same run.
        b.get(url)
        wait(b, "the run in a second browser", lambda d: "RL16-0042" in text_of(d, "#run-title"))
        wait(b, "the prompt in a second browser", ec.visibility_of_element_located((By.ID, "prompt")))

        # Answer; the run goes on to its verdict.
        a.find_element(By.ID, "prompt-ok").click()
        wait(a, "PASS", lambda d: d.find_elements(By.CSS_SELECTOR, ".verdict.pass"))
        wait(b, "PASS in the second browser", lambda d: d.find_elements(By.CSS_SELECTOR, ".verdict.pass"))
        rows = a.find_elements(By.CSS_SELECTOR, "#meas tbody tr")
        assert len(rows) == 2, f"{len(rows)} measurements"
        assert all(r.find_elements(By.CSS_SELECTOR, "td.pass") for r in rows)
        assert a.find_elements(By.CSS_SELECTOR, "#steps li.done")
        supply = text_of(a, "#supply")
        assert supply.startswith("Unit's supply: 15.00 V, 0.550 A (8.25 W), output on"), supply
        report = a.find_element(By.ID, "report-link").get_attribute("href")
        a.get(report)
        wait(a, "the report page", lambda d: "PASS" in d.find_element(By.CSS_SELECTOR, ".verdict").text)
        a.back()

        # Abort at the prompt: confirmed, cleanup, ABORTED.
        start_smoke(a, "RL16-0043")
        wait(a, "the prompt of the second run", lambda d: "RL16-0043" in text_of(d, "#run-title") and d.find_element(By.ID, "prompt").is_displayed())
        a.find_element(By.ID, "abort").click()
        wait(a, "the abort confirmation", ec.alert_is_present(), 10)
        a.switch_to.alert.accept()
        wait(a, "ABORTED", lambda d: d.find_elements(By.CSS_SELECTOR, ".verdict.aborted"))
        assert "Bench left" in text_of(a, "#verdict-box"), text_of(a, "#verdict-box")
        assert "cleanup" in text_of(a, "#events"), text_of(a, "#events")
        print("station page: start refused without a serial, prompt, reload, second browser, PASS, the unit's supply, report, abort: ok")
    finally:
        a.quit()
        b.quit()


if __name__ == "__main__":
    t0 = time.time()
    main()
    print(f"in {time.time() - t0:.1f} s")
