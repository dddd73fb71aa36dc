"""The station page as an operator uses it, in a real headless Chromium
driven over WebDriver (selenium, Debian's chromium-driver).

    station_browser.py URL [CHROMEDRIVER]
    station_browser.py --batch URL [CHROMEDRIVER] [SCREENSHOT.png]
    station_browser.py --sign URL [CHROMEDRIVER] [SCREENSHOT.png]

URL is the one `gyrobench station` prints (with its token). Runs the smoke
procedure: types the serial and the operator (Enter, as a barcode scanner
sends), ticks the checklist, starts (the form empties for the next unit),
sees the bench named as simulated, the current step beside the status, the
steps advance and the prompt (no read-out before the first second), reloads mid-run (the same state comes back),
opens a second browser (it sees the same run), answers the prompt, sees
PASS, the read-out's numbers (the drift named by its window: the last
60 s of the last record; chamber, case, block, table) and the drift
chart's title, the Abort button greyed, the unit's history refreshed with a link to
the report, and the report; then starts again and aborts at the prompt:
cleanup runs, the verdict is ABORTED, and the first run's report is still
served.
With --batch, against a station on a bench with slots (quad.toml): one
serial field per slot (Enter moves to the next slot), two slots filled and
two left empty, the form empty again after the start, one tile per unit
with its drift (the mean of the last 60 s of its record, the window named),
each tile's verdict PASS and its own report (the
unit's serial on it); the page is saved as SCREENSHOT.png when asked.
With --sign, against a station whose last run (RL16-0042) was reviewed by
A. Quality: the unit's history marks the run reviewed and lists the
signature (role, who, when); approving it as A. Quality is refused with the
store's words under the form; approving it as B. Lead is accepted and the
list and the history's mark update; the page is saved as SCREENSHOT.png
when asked.
Exits non-zero with the step that failed.
"""

import re
import sys
import time

from selenium import webdriver
from selenium.common.exceptions import StaleElementReferenceException
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support import expected_conditions as ec
from selenium.webdriver.support.ui import WebDriverWait


def browser(driver_path, size="1400,1000"):
    opts = webdriver.ChromeOptions()
    for a in ("--headless=new", "--no-sandbox", "--disable-gpu", f"--window-size={size}"):
        opts.add_argument(a)
    service = Service(executable_path=driver_path) if driver_path else Service()
    return webdriver.Chrome(options=opts, service=service)


def wait(d, what, cond, timeout=60):
    # The page redraws its live parts (the tiles, the read-out) on every
    # update: an element read as it is replaced is "not yet", polled again.
    try:
        return WebDriverWait(d, timeout, ignored_exceptions=(StaleElementReferenceException,)).until(cond)
    except Exception as e:  # noqa: BLE001 - say which step failed
        sys.exit(f"station page: {what}: not seen within {timeout} s ({type(e).__name__})")


def fresh(d, read, tries=50):
    """`read(d)`, read again when the page redrew what it was reading."""
    for _ in range(tries - 1):
        try:
            return read(d)
        except StaleElementReferenceException:
            continue
    return read(d)


def tile_texts(d, css=None):
    """Each unit tile's text (or that of its `css` part), read whole."""
    return fresh(d, lambda d: [
        (t.find_element(By.CSS_SELECTOR, css) if css else t).text
        for t in d.find_elements(By.CSS_SELECTOR, "#units .tile")
    ])


def text_of(d, css):
    return fresh(d, lambda d: d.find_element(By.CSS_SELECTOR, css).text)


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
        # The form is empty for the next unit: no serial, nothing ticked.
        wait(a, "the serial field emptied by the start", lambda d: d.find_element(By.ID, "serial").get_attribute("value") == "")
        assert not any(c.is_selected() for c in a.find_elements(By.CSS_SELECTOR, "#checklist input")), "the checklist stayed ticked"
        bench = text_of(a, "#bench")
        assert "embedded" in bench and "simulated" in bench, bench
        wait(a, "the prompt", ec.visibility_of_element_located((By.ID, "prompt")))
        assert "connector" in text_of(a, "#prompt-text"), text_of(a, "#prompt-text")
        # At the setup's prompt no record is taken yet: the read-out, once
        # the run has read the bench (it switched the unit on at its
        # start), shows no drift.
        assert not a.find_element(By.ID, "readout").is_displayed() or "no record yet" in text_of(a, "#readout"), text_of(a, "#readout")
        steps_before = text_of(a, "#steps li.current")
        now = text_of(a, "#now")
        assert now.startswith("Now: step ") and steps_before in now, f"{now!r} against {steps_before!r}"
        assert a.find_element(By.ID, "now").location["y"] < a.find_element(By.ID, "c-rate").location["y"], "the current step sits below the charts"
        enabled_bg = a.find_element(By.ID, "abort").value_of_css_property("background-color")

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
        abort = a.find_element(By.ID, "abort")
        assert not abort.is_enabled(), "Abort enabled after the run"
        disabled_bg = abort.value_of_css_property("background-color")
        assert disabled_bg != enabled_bg, f"Abort looks the same disabled ({disabled_bg}) as enabled"
        assert not a.find_element(By.ID, "now").is_displayed(), "a current step after the run"
        # The unit's history refreshed by the run's end, linking its report.
        wait(a, "the unit's history with this run", lambda d: d.find_elements(By.CSS_SELECTOR, "#history tr td.pass"))
        stored = a.find_element(By.CSS_SELECTOR, "#history tr td a").get_attribute("href")
        # The read-out gives the bench and the unit in numbers, the drift
        # named by its window; the drift chart says what it shows.
        readout = {k: text_of(a, f"#now-{k} .val") for k in ("drift", "chamber", "case", "block", "table")}
        assert re.fullmatch(r"[+-]\d+\.\d{3} deg/h", readout["drift"]), readout
        assert re.fullmatch(r"\+20\.\d\d degC", readout["chamber"]), readout
        assert re.fullmatch(r"-?\d+\.\d\d degC", readout["case"]), readout
        assert re.fullmatch(r"-?\d+\.\d\d / -?\d+\.\d\d", readout["block"]), readout
        assert re.fullmatch(r"-?\d+\.\d\d / -?\d+\.\d\d", readout["table"]), readout
        window = text_of(a, "#now-drift .w")
        assert window == "mean of the last 60 s of record east (ended)", window
        title = text_of(a, "#c-rate .u-title")
        assert title.startswith("Drift") and "records" in title and "slews" in title, title
        supply = text_of(a, "#supply")
        assert supply.startswith("Unit's supply: 15.00 V, 0.550 A (8.25 W), output on"), supply
        report = a.find_element(By.ID, "report-link").get_attribute("href")
        a.get(report)
        wait(a, "the report page", lambda d: "PASS" in d.find_element(By.CSS_SELECTOR, ".verdict").text)
        a.get(stored)
        wait(a, "the report from the unit's history", lambda d: "PASS" in d.find_element(By.CSS_SELECTOR, ".verdict").text)
        a.get(url)

        # Abort at the prompt: confirmed, cleanup, ABORTED.
        start_smoke(a, "RL16-0043")
        wait(a, "the prompt of the second run", lambda d: "RL16-0043" in text_of(d, "#run-title") and d.find_element(By.ID, "prompt").is_displayed())
        a.find_element(By.ID, "abort").click()
        wait(a, "the abort confirmation", ec.alert_is_present(), 10)
        a.switch_to.alert.accept()
        wait(a, "ABORTED", lambda d: d.find_elements(By.CSS_SELECTOR, ".verdict.aborted"))
        assert "Bench left" in text_of(a, "#verdict-box"), text_of(a, "#verdict-box")
        assert "cleanup" in text_of(a, "#events"), text_of(a, "#events")
        # The first run's report is still served.
        a.get(report)
        wait(a, "the first run's report after a second run", lambda d: "PASS" in d.find_element(By.CSS_SELECTOR, ".verdict").text)
        print("station page: start refused without a serial, an empty form after a start, the bench named, the current step by the status, prompt, reload, second browser, PASS, the read-out in numbers and the drift chart named, Abort greyed, the history's report link, the unit's supply, report, abort, an earlier report kept: ok")
    finally:
        a.quit()
        b.quit()


def batch(url, driver_path, shot):
    a = browser(driver_path)
    try:
        a.get(url)
        wait(a, "procedures listed", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#procedure option")) > 0)
        wait(a, "a serial field per slot", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#slot-serials input")) == 4)
        assert not a.find_element(By.ID, "serial").is_displayed(), "the one-unit serial field shows on a bench with slots"
        a.find_element(By.CSS_SELECTOR, "#procedure option[value='smoke.toml']").click()
        a.find_element(By.ID, "serial-A").send_keys("RL16-0101", Keys.ENTER)
        wait(a, "Enter moves to the next slot", lambda d: d.switch_to.active_element.get_attribute("id") == "serial-B")
        a.find_element(By.ID, "serial-C").send_keys("RL16-0103", Keys.ENTER)
        a.find_element(By.ID, "operator").send_keys("ann")
        for box in a.find_elements(By.CSS_SELECTOR, "#checklist input[type=checkbox]"):
            box.click()
        a.find_element(By.ID, "start").click()
        wait(a, "a tile per unit", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#units .tile")) == 2)
        assert all(i.get_attribute("value") == "" for i in a.find_elements(By.CSS_SELECTOR, "#slot-serials input")), "a slot's serial stayed after the start"
        tiles = tile_texts(a)
        assert len(tiles) == 2, tiles
        assert "Slot A" in tiles[0] and "RL16-0101" in tiles[0], tiles[0]
        assert "Slot C" in tiles[1] and "RL16-0103" in tiles[1], tiles[1]
        assert "2 units" in text_of(a, "#run-title"), text_of(a, "#run-title")
        wait(a, "the prompt", ec.visibility_of_element_located((By.ID, "prompt")))
        a.find_element(By.ID, "prompt-ok").click()
        wait(a, "PASS on every tile", lambda d: len(d.find_elements(By.CSS_SELECTOR, "#units .tile .v.pass")) == 2)
        rates = tile_texts(a, ".rate")
        assert all(re.fullmatch(r"drift [+-]\d+\.\d{3} deg/h", r) for r in rates) and rates[0] != rates[1], f"the tiles' rates: {rates}"
        windows = tile_texts(a, ".window")
        assert all(w == "mean of the last 60 s of record east (ended)" for w in windows), f"the tiles' windows: {windows}"
        wait(a, "the batch's verdict", lambda d: d.find_elements(By.CSS_SELECTOR, ".verdict.pass"))
        assert not a.find_elements(By.ID, "report-link"), "a batch has no single report"
        if shot:
            a.save_screenshot(shot)
        links = [e.get_attribute("href") for e in a.find_elements(By.CSS_SELECTOR, "#units .tile a.unit-report")]
        assert len(links) == 2, links
        for serial, link in zip(["RL16-0101", "RL16-0103"], links):
            a.get(link)
            wait(a, f"the report of {serial}", lambda d: "PASS" in d.find_element(By.CSS_SELECTOR, ".verdict").text)
            assert serial in a.page_source, f"{serial} not on its report"
        print("station page, batch: a serial field per slot, Enter to the next slot, empty slots, an empty form after the start, a tile per unit with its drift over a named window and its verdict, each unit's report: ok")
    finally:
        a.quit()


def sign(url, driver_path, shot):
    # Tall enough for the history's signing form beside the run (the
    # screenshot); the charts take their width when first drawn.
    a = browser(driver_path, "1280,1400")
    try:
        a.get(url)
        # The finished run's unit: its history, the run chosen for signing.
        wait(a, "the signing form under the unit's history", ec.visibility_of_element_located((By.ID, "signing")))
        wait(a, "the review listed", lambda d: "reviewed by A. Quality" in text_of(d, "#signatures"))
        listed = text_of(a, "#signatures li")
        assert re.search(r"reviewed by A\. Quality, \d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", listed), listed
        assert "reviewed" in text_of(a, "#history tr.chosen td.pass"), text_of(a, "#history tr.chosen")
        run = a.find_element(By.CSS_SELECTOR, "#history tr.chosen").get_attribute("data-run")
        assert run and run in text_of(a, "#sign-run"), (run, text_of(a, "#sign-run"))

        # The reviewer approves: refused, in the store's words.
        a.find_element(By.CSS_SELECTOR, "#sign-role option[value='approved']").click()
        a.find_element(By.ID, "sign-by").send_keys("A. Quality")
        a.find_element(By.ID, "sign").click()
        wait(a, "the reviewer's approval refused", lambda d: "another person approves it" in text_of(d, "#sign-refusal"))
        assert len(a.find_elements(By.CSS_SELECTOR, "#signatures li")) == 1, text_of(a, "#signatures")

        # Someone else approves: listed, the refusal gone, the row marked.
        by = a.find_element(By.ID, "sign-by")
        by.clear()
        by.send_keys("B. Lead")
        a.find_element(By.ID, "sign-note").send_keys("released")
        a.find_element(By.ID, "sign").click()
        wait(a, "the approval listed", lambda d: "approved by B. Lead" in text_of(d, "#signatures"))
        items = fresh(a, lambda d: [li.text for li in d.find_elements(By.CSS_SELECTOR, "#signatures li")])
        assert len(items) == 2 and items[1].startswith("approved by B. Lead") and items[1].endswith("released"), items
        assert text_of(a, "#sign-refusal") == "", text_of(a, "#sign-refusal")
        assert "approved" in text_of(a, "#history tr.chosen td.pass"), text_of(a, "#history tr.chosen")
        assert a.find_element(By.ID, "sign-note").get_attribute("value") == "", "the note stayed for the next signature"
        if shot:
            a.execute_script("window.scrollTo(0, 0)")
            a.save_screenshot(shot)
        print("station page, signing: the history marks the review and lists it, the reviewer's approval refused in words, another person's approval listed: ok")
    finally:
        a.quit()


if __name__ == "__main__":
    t0 = time.time()
    if len(sys.argv) > 1 and sys.argv[1] == "--batch":
        args = sys.argv[2:] + [None, None]
        batch(args[0], args[1], args[2])
    elif len(sys.argv) > 1 and sys.argv[1] == "--sign":
        args = sys.argv[2:] + [None, None]
        sign(args[0], args[1], args[2])
    else:
        main()
    print(f"in {time.time() - t0:.1f} s")
