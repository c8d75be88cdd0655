"""The monitor's page in a real browser: headless Chromium (Debian's package, /usr/bin/chromium)
loads it during a `--fast` job on a loopback bus; the page's DOM shows the job and a
machine id without a service, and the screenshot's chart area holds the drawn lines of the
feed and of both axes (pixels of their colours). Skipped where Chromium is absent."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile

import pytest

from test_clients_bus import bus_env, lookahead, stop, wait_alive, wait_subscribed
from test_monitor_bus import get, poll, start_monitor

CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium"
                                        if os.path.exists("/usr/bin/chromium") else None)
pytestmark = [
    pytest.mark.bus, pytest.mark.filterwarnings("ignore::ResourceWarning"),
    pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (Debian package "
                       "`chromium`); the page is tested in a browser only where it is"),
]
#: colours the page draws the feed and the first two axes with (monitor.js)
FEED, AXIS_X, AXIS_C = (230, 237, 243), (79, 195, 247), (255, 169, 77)


def chromium(url: str, *mode: str, timeout_ms: int = 6000) -> subprocess.CompletedProcess:
    """One headless Chromium run on `url` (flags for root on a machine without network);
    `--timeout` (not a virtual-time budget: the page's event stream never ends) stops
    loading after `timeout_ms`, then the screenshot or DOM dump is taken."""
    with tempfile.TemporaryDirectory(prefix="monitor-chromium-") as profile:
        return subprocess.run(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
             "--no-first-run", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", f"--user-data-dir={profile}",
             "--window-size=1280,900", "--hide-scrollbars", f"--timeout={timeout_ms}",
             *mode, url], capture_output=True, text=True, timeout=120)


def count_colour(img, box: tuple[int, int, int, int], rgb: tuple[int, int, int],
                 tol: int = 40) -> int:
    """Pixels of `img` inside `box` (left, top, width, height) within `tol` of `rgb`."""
    left, top, width, height = box
    crop = img.convert("RGB").crop((left, top, left + width, top + height))
    return sum(1 for px in crop.get_flattened_data()
               if all(abs(a - b) <= tol for a, b in zip(px, rgb, strict=True)))


def test_page_draws_the_chart_during_a_fast_job(tmp_path):
    image = pytest.importorskip("PIL.Image")
    env = bus_env("heuristic")
    service = lookahead(env, "serve", "--fast", "--log-level", "WARNING")
    winder = lookahead(env, "winder", "--fast", "--jobs", "1")
    procs = [service, winder]
    try:
        monitor, url = start_monitor(env, "--machine-id", "winder,nobody")
        procs.append(monitor)
        wait_alive(env, "planner", "machine")
        wait_subscribed(env, "setpoints")
        poll(url, "winder", lambda s: s["service"] == "up", what="the service")
        # paced: 36 segments over ~1.8 s, so the job is under way when the browser loads
        procs.append(lookahead(env, "publish", "tube-9570", "--job", "browser", "--chunk",
                               "400", "--rate", "20", "--quiet", "--timeout", "90"))
        poll(url, "winder", lambda s: s["job"] == "browser" and s["rows"]
             and s["rows"][-1]["t"] > 2.0, what="2 s of setpoints")
        shot = tmp_path / "monitor.png"
        out = chromium(url, f"--screenshot={shot}")
        assert shot.exists(), out.stderr[-2000:]
        # the DOM is dumped at the load event (after /api/boot.js drew the first picture);
        # the long stop only matters on a machine so loaded that loading takes that long
        dom = chromium(url, "--dump-dom", timeout_ms=30000).stdout
        state = get(url, "/api/state?machine=winder")
    finally:
        stop(*procs)
    # the DOM: the job, its state, and the machine without a service
    assert 'data-machine="winder"' in dom and "job browser" in dom, dom[-3000:]
    assert re.search(r'data-machine="nobody"[^>]*data-service="none"', dom), dom[:3000]
    assert "No service on lookahead/nobody" in dom
    match = re.search(r'data-chart-rect="(\d+),(\d+),(\d+),(\d+)"', dom)
    assert match, dom[:2000]
    box = tuple(int(g) for g in match.groups())
    points = int(re.search(r'data-chart-points="(\d+)"', dom).group(1))
    assert points > 100 and box[2] > 400 and box[3] > 200
    # the screenshot: lines of the feed and of both axes inside the chart's rectangle
    img = image.open(shot)
    assert img.size == (1280, 900)
    for colour in (FEED, AXIS_X, AXIS_C):
        assert count_colour(img, box, colour) > 150, colour
    assert state["rows"] and state["gaps"] == 0
