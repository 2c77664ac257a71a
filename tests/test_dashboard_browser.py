"""A real browser (headless Chromium, driven by Playwright) on the live dashboard while
the demo replays: the ZMP readout moves and shows the offline analysis' numbers, the
top view redraws, the alarm of the demo's forward lean appears; a screenshot is saved."""

from __future__ import annotations

import threading
import time

import pytest
from playwright.sync_api import sync_playwright

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import trajectory_frames
from livezmp.monitor.dashboard import DashboardServer
from livezmp.monitor.loop import Monitor
from livezmp.sources.file_replay import FileReplaySource

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
SPEED = 3.0  # the demo leans out of support at t ≈ 6.6 s: about 2.2 s into the replay


@pytest.fixture
def live_demo():
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names)
    frames = trajectory_frames(body, traj)
    cfg = default_config(body, 100.0)
    offline = {r.index: r for r in Pipeline(body, cfg, 0.01).run(traj.t, frames)}
    src = FileReplaySource("<demo>", body, spec, traj.t, frames, speed=SPEED)
    mon = Monitor(src, cfg, alarm_after=0.2)
    server = DashboardServer("127.0.0.1", 0, mon.status, {"source": "<demo>", "body": "urdf body",
                                                           "alarm_after": 0.2}, token=True)
    url = server.start()
    mon.listeners.append(server)
    stop = threading.Event()
    runner = threading.Thread(target=mon.run, args=(stop,))
    yield url, offline, runner
    stop.set()
    if runner.is_alive():
        runner.join(10)
    server.stop()


def test_dashboard_in_a_browser(live_demo, tmp_path):
    url, offline, runner = live_demo
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
            page.goto(url)
            page.wait_for_selector("#conn.on", timeout=10000)
            runner.start()
            shown, pictures = {}, set()
            end = time.monotonic() + 30
            while page.query_selector("#alarm-list li.raised") is None and time.monotonic() < end:
                index, text = page.evaluate(
                    "() => [window.livezmp.frame && window.livezmp.frame.index, "
                    "document.getElementById('zmp-readout').textContent]")
                if index is not None and text != "–":
                    shown[index] = text
                pictures.add(page.evaluate("() => document.getElementById('top').toDataURL().length"))
                page.wait_for_function(  # the next frame drawn, or the alarm
                    "i => document.querySelector('#alarm-list li.raised') || "
                    "(window.livezmp.frame && window.livezmp.frame.index !== i)", arg=index, timeout=10_000)
            alarm = page.query_selector("#alarm-list li.raised")
            assert alarm is not None and "ALARM: ZMP out of support" in alarm.text_content()
            assert len(set(shown.values())) >= 4, shown  # the ZMP readout moved
            for index, text in shown.items():  # and showed the offline analysis' ZMP of that frame
                # The readout is mm-rounded from the feed's 10 µm-rounded value: within half a mm
                # plus the feed's rounding (an exact string match failed at a rounding tie in CI).
                x, y = (float(v) for v in text.split(","))
                zmp = offline[index].zmp
                assert abs(x - zmp[0]) <= 0.0005 + 1e-5 and abs(y - zmp[1]) <= 0.0005 + 1e-5, (text, zmp)
            assert len(pictures) >= 3  # the top view was redrawn with new content
            assert page.text_content("#alarm-count") == "1 raised"
            shot = tmp_path / "dashboard.png"
            page.screenshot(path=str(shot), full_page=True)
            assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20000
            assert errors == []
        finally:
            browser.close()
