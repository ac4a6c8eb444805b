"""The scope's page in a real headless browser (Chromium through Selenium): live traces update, the view's slider moves.

Needs the Debian packages ``chromium`` and ``chromium-driver`` and selenium from PyPI; skipped, with the reason,
only when one of them is absent.
"""

import json
import shutil
import threading
import time
import urllib.request

import numpy as np
import pytest

CHROMIUM, DRIVER = shutil.which("chromium"), shutil.which("chromedriver")


@pytest.fixture
def browser():
    if CHROMIUM is None or DRIVER is None:
        pytest.skip("chromium and chromium-driver are not installed (apt-get install -y chromium chromium-driver)")
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install selenium)")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(flag)
    options.binary_location = CHROMIUM
    driver = webdriver.Chrome(options=options, service=Service(executable_path=DRIVER))
    yield driver
    driver.quit()


def _until(condition, what, seconds=30.0):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"the page did not {what} within {seconds:g} s")


def _pixels(driver, index):
    return driver.execute_script(f"return document.getElementById('c{index}').toDataURL();")


def test_the_live_page_draws_the_sync_run_as_it_goes(lsl, streamer, stream_name, browser):
    from cogblocks.data.groups import TABLE2
    from cogblocks.live import live_sync, run_realtime
    from cogblocks.live.scope import Scope

    omega = np.asarray(TABLE2[1].omega)
    streamer(f"{stream_name}-phases", lambda t: np.mod(omega * t, 2 * np.pi), channels=TABLE2[1].n, unit="rad")
    compiled = live_sync(f"{stream_name}-phases", f"{stream_name}-l2", group=1, motion="mean").compile(0.01)
    scope = Scope.for_diagram(compiled, title="sync test")
    meta = json.loads(urllib.request.urlopen(scope.url + "meta").read())
    assert [p["title"] for p in meta["panels"]] == [
        "inputs",
        "phases (rad)",
        "θ_L2 − θ_L0 (rad)",
        "λ (rad)",
        "r",
        "late ticks (cumulative)",
    ]
    assert meta["panels"][1]["series"] == ["theta_l2", "theta_l0"] and meta["mode"] == "live"
    reports = []
    runner = threading.Thread(target=lambda: reports.append(run_realtime(compiled, 6.0, scope=scope)), daemon=True)
    try:
        browser.get(scope.url)
        runner.start()
        _until(lambda: browser.execute_script("return window.scope.draws") > 0, "draw")
        ticks = browser.execute_script("return window.scope.ticks")
        before = [_pixels(browser, i) for i in range(len(meta["panels"]))]
        _until(lambda: browser.execute_script("return window.scope.ticks") > ticks + 50, "receive 50 more ticks")
        _until(lambda: _pixels(browser, 0) != before[0] and _pixels(browser, 1) != before[1], "redraw the traces")
        status = browser.find_element("id", "status").text
        assert status.startswith("ticks ") and "late ticks" in status
        runner.join(timeout=30)
        (report,) = reports
        assert report.ticks == 600
        # every tick reached the page, in order: its count is the run's
        _until(lambda: browser.execute_script("return window.scope.ticks") == 600, "receive every tick")
        assert browser.execute_script("return data.t.length") == 600
        r = browser.execute_script("return data.r.map(v => v[0])")
        assert all(v is None or 0.0 <= v <= 1.0 for v in r) and sum(v is not None for v in r) > 500
    finally:
        scope.close()


def test_the_view_page_shows_a_saved_run_with_a_time_slider(browser, tmp_path):
    from cogblocks.live.runner import RealtimeReport, save_report
    from cogblocks.live.scope import ScopeView
    from cogblocks.live.view import load_run
    from cogblocks.sim import Trace

    n = 3000
    t = 0.01 * np.arange(n)
    trace = Trace(t, {"theta": np.mod(2 * np.pi * 0.5 * t, 2 * np.pi), "sample": np.sin(t)[:, None]}, {})
    late = np.zeros(n)
    late[[100, 2000]] = 20.0  # two ticks started 20 ms late
    report = RealtimeReport(n, 2, 0, np.full(n, 1.0), late, 0, 0, np.nan, trace=trace)
    path = save_report(report, tmp_path / "run.npz")
    times, signals, units, flags = load_run(path)
    assert set(signals) == {"theta", "sample"} and flags.sum() == 2
    scope = ScopeView(times, signals, units, flags, title="view test")
    try:
        browser.get(scope.url)
        _until(lambda: browser.execute_script("return window.scope.draws") > 0, "draw")
        assert browser.execute_script("return window.scope.window") == pytest.approx([0.0, 10.0])
        assert browser.find_element("id", "status").text.endswith("late ticks 1")
        before = _pixels(browser, 1)
        browser.execute_script(
            "const s = document.getElementById('slider'); s.value = 25; s.dispatchEvent(new Event('input'));"
        )
        _until(lambda: browser.execute_script("return window.scope.window")[1] == 25.0, "move to 25 s")
        assert browser.execute_script("return window.scope.window") == pytest.approx([15.0, 25.0])
        _until(lambda: _pixels(browser, 1) != before, "redraw the window")
        assert browser.find_element("id", "status").text.endswith("late ticks 2")
    finally:
        scope.close()


def test_view_refuses_what_it_cannot_show(tmp_path):
    from cogblocks.live.view import load_run

    with pytest.raises(ValueError, match=r"run\.csv: no such file"):
        load_run(tmp_path / "run.csv")
    (tmp_path / "run.csv").write_text("t\n0\n")
    with pytest.raises(ValueError, match=r"run\.csv: cogblocks view shows \.npz traces and \.xdf files, not \.csv"):
        load_run(tmp_path / "run.csv")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match=r"other\.npz: holds no trace"):
        load_run(tmp_path / "other.npz")
