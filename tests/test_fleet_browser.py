"""The fleet web page in a real headless browser (Debian's chromium and chromium-driver,
driven by selenium): a small simulated fleet judged, its page opened from disk and served
by `monitor fleet serve`, the table read, a machine page clicked, an alarm acknowledged.

A screenshot of each page is kept in the test's folder (``pytest --basetemp``)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.fleet_support import env, fleet_cmd, free_port, kill, make_fleet, wait_for

CHROMIUM, DRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
pytestmark = pytest.mark.skipif(
    not (CHROMIUM.is_file() and DRIVER.is_file()),
    reason="needs Debian's chromium and chromium-driver (apt-get install chromium "
    "chromium-driver; .ci/run installs them)",
)
webdriver = pytest.importorskip("selenium.webdriver", reason="needs selenium ([test] extra)")


@pytest.fixture(scope="module")
def judged(tmp_path_factory):
    """FLEET and its RESULTS: M01 piston wear, M02 spool wear (neither alarms in two short
    days), M03 QP frozen from day 2, and the reference machine (its folder ``reference``)
    without commissioning data, judged with the shipped model, which was commissioned on it
    and isolates faults, on the shipped demo logs (recordings of it): normal on day 1, a
    piston seal leaking on day 2.  (Any other machine's folder would withhold its alarm.)"""
    from monitor.resources import resource_path

    where = tmp_path_factory.mktemp("browser")
    fleet = make_fleet(where, tmp_path_factory)
    ref = fleet / "reference" / "logs"
    ref.mkdir(parents=True)
    for day, name in ((1, "normal.log"), (2, "piston_wear.log")):
        shutil.copyfile(resource_path("replay", name), ref / f"day{day:02d}.log")
    results = where / "results"
    proc = subprocess.run(
        fleet_cmd(str(fleet), "--out", str(results), "--workers", "1"),
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 0, proc.stderr
    return fleet, results


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = str(CHROMIUM)
    profile = tmp_path_factory.mktemp("chromium-profile")
    for flag in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={profile}",
        "--window-size=1400,1100",
    ):
        opts.add_argument(flag)
    driver = webdriver.Chrome(service=Service(str(DRIVER)), options=opts)
    driver.implicitly_wait(20)  # a generous bound for the page to render, not a timing check
    yield driver
    driver.quit()


def _cells(driver, machine: str) -> list[str]:
    from selenium.webdriver.common.by import By

    return [td.text for td in driver.find_elements(By.CSS_SELECTOR, f"#row-{machine} td")]


def _text_after_click(driver, selector: str, expect: str) -> str:
    """The text of ``selector`` once the page a click loads shows ``expect`` in it (an
    element of the page before the click goes stale, and is looked up again)."""
    from selenium.common.exceptions import NoSuchElementException, StaleElementReferenceException
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    def shown(d):
        text = d.find_element(By.CSS_SELECTOR, selector).text
        return text if expect in text else False

    ignore = (StaleElementReferenceException, NoSuchElementException)
    # A generous bound for a page to load, not a timing check.
    return WebDriverWait(driver, 60, ignored_exceptions=ignore).until(shown)


def _plot_drawn(driver) -> bool:
    """plotly ran in the page: it draws its SVG into the div."""
    from selenium.webdriver.common.by import By

    return bool(driver.find_elements(By.CSS_SELECTOR, "div.js-plotly-plot svg.main-svg"))


def test_the_static_page_opens_from_disk_with_its_plots_and_names(judged, browser, tmp_path):
    fleet, results = judged
    out = tmp_path / "page"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "fleet",
            "report",
            str(results),
            "--html",
            str(out),
            "--fleet",
            str(fleet),
        ],
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 0, proc.stderr
    browser.get((out / "index.html").as_uri())
    assert _plot_drawn(browser)  # plotly.min.js beside the page, no network
    m01, m02, m03, ref = (_cells(browser, m) for m in ("M01", "M02", "M03", "reference"))
    # The reference machine's piston seal leaks on day 2: the fault by name, since then, and
    # what to do.
    assert ref[1] == "FAULT" and ref[2].startswith("piston_wear: piston seal suspected")
    assert ref[3] == "day02" and ref[5].startswith("inspect the boom cylinder")
    # M03's flow sensor froze on day 2: named, since then, and what to do.
    assert m03[1] == "SENSOR FAULT" and m03[3] == "day02"
    assert m03[2] == "QP frozen\nQP: pump outlet flow (L/min)"  # the name, then what it is
    assert m03[5].startswith("check the sensor and its wiring")
    for cells in (m01, m02):  # every state is a word of the table, and says what to do
        assert cells[1] in ("FAULT", "healthy", "WEARING?") and cells[5]
    browser.save_screenshot(str(tmp_path / "index.png"))
    browser.get((out / "alarms.html").as_uri())
    assert "monitor fleet serve RESULTS" in browser.page_source


def test_serve_drills_down_and_acknowledges_an_alarm_into_the_file(judged, browser, tmp_path):
    from selenium.webdriver.common.by import By

    fleet, results = judged
    shutil.copytree(results, tmp_path / "results")
    results = tmp_path / "results"
    port = free_port()
    log = (tmp_path / "serve.log").open("w")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "monitor",
            "fleet",
            "serve",
            str(results),
            "--fleet",
            str(fleet),
            "--port",
            str(port),
        ],
        stderr=log,
        env=env(),
        start_new_session=True,
    )
    try:
        wait_for(lambda: "http://" in (tmp_path / "serve.log").read_text(), "the address", proc)
        browser.get(f"http://127.0.0.1:{port}/")
        browser.find_element(By.LINK_TEXT, "M03").click()
        assert "SENSOR FAULT" in _text_after_click(browser, "h1", "M03")
        assert browser.current_url.endswith("/machine-M03.html")
        episodes = browser.find_element(By.ID, "episodes").text
        assert "QP frozen" in episodes and "520215" in episodes  # SPN of QP (by hand)
        assert _plot_drawn(browser)
        browser.save_screenshot(str(tmp_path / "machine-M03.png"))

        browser.find_element(By.LINK_TEXT, "Alarm list").click()
        _text_after_click(browser, "h1", "Alarm list")
        row = browser.find_elements(By.CSS_SELECTOR, "#alarms tr[data-alarm]")[0]
        alarm = row.get_attribute("data-alarm")
        row.find_element(By.NAME, "by").send_keys("Ana Field")
        row.find_element(By.NAME, "note").send_keys("parts ordered")
        row.find_element(By.CSS_SELECTOR, "button[value=acknowledge]").click()
        status = _text_after_click(browser, f'tr[data-alarm="{alarm}"] td.status', "acknowledged")
        assert re.match(
            r"acknowledged by Ana Field at \d{4}-\d\d-\d\d \d\d:\d\d: parts ordered", status
        ), status
        browser.save_screenshot(str(tmp_path / "alarms.png"))
        # The machine page shows it too (made anew on each request).
        link = browser.find_element(By.CSS_SELECTOR, f'tr[data-alarm="{alarm}"] a')
        browser.get(link.get_attribute("href"))
        assert "acknowledged by Ana Field" in _text_after_click(
            browser, "#episodes", "acknowledged"
        )
    finally:
        kill(proc)
        log.close()
    lines = (results / "alarm-acks.jsonl").read_text().splitlines()
    saved = json.loads(lines[-1])
    assert (saved["alarm"], saved["action"], saved["by"]) == (alarm, "acknowledge", "Ana Field")
