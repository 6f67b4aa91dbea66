"""CPU of the participant page's views in real Chromium (software WebGL): the page idle in 3D and in 2D, then
viser's viewer page alone at the frame's size, paced (frontend/viewer-pacing.js) and with viser's own loop
(`pacing=off`), with and without fixedDpr=0.5: idle, and while the robot places an object (live view); last the
page on a query once the robot's recorded attempt has played (viser's player holds its last pose).

    .venv/bin/python benchmarks/bench_view_idle.py [--idle-seconds 10] [--viewport 1366x768]

Each figure is the CPU time of every Chromium process this benchmark started (/proc, as bench_participant.py
counts it) over a quiet stretch of a demonstration screen (or over one placement, about 5.6 s of motion at the
robot's real speed), as a share of one core; with the number of frames viser's client drew when paced.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "browser"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import httpx  # noqa: E402

from bench_participant import chromium_cpu_seconds, wait_watching  # noqa: E402
from conftest import LiveServer, launch_chromium  # noqa: E402
from tests.web.conftest import open_study, study_spec  # noqa: E402

PACING = "() => ({ ...(window.tableteachPacing || {}) })"  # frontend/viewer-pacing.js's counters
OBJECTS = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]


def report(what: str, seconds: float, cpu: float, before: dict[str, Any], after: dict[str, Any]) -> None:
    drawn = f", {after['frames'] - before['frames']} frames drawn" if "frames" in after else ""
    print(f"{what}: {100 * cpu / seconds:.1f}% of one core over {seconds:.1f} s{drawn}", flush=True)


def measure(what: str, seconds: float, frame: Any = None) -> None:
    """Print the Chromium processes' CPU share over the next `seconds` (and the frames viser's client drew in
    `frame`, a Playwright Frame of the viewer page)."""
    before = frame.evaluate(PACING) if frame is not None else {}
    c0, t0 = chromium_cpu_seconds(), time.monotonic()
    time.sleep(seconds)
    cpu, elapsed = chromium_cpu_seconds() - c0, time.monotonic() - t0
    report(what, elapsed, cpu, before, frame.evaluate(PACING) if frame is not None else {})


def moving(server: LiveServer, key: str) -> bool:
    activity = server.ctx.robot.activity(key)
    return activity is not None and activity.moving


def measure_placement(what: str, server: LiveServer, key: str, token: str, obj: str, frame: Any) -> None:
    """Print the CPU share while the robot places `obj` (from the request until the robot is still)."""
    before = frame.evaluate(PACING)
    c0, t0 = chromium_cpu_seconds(), time.monotonic()
    httpx.post(f"{server.url}/api/v1/me/placements", json={"object": obj},
               headers={"Authorization": f"Bearer {token}"}, timeout=60).raise_for_status()
    deadline = time.monotonic() + 30
    while not moving(server, key) and time.monotonic() < deadline:  # the placement's physics runs first
        time.sleep(0.02)
    while moving(server, key):
        time.sleep(0.05)
    cpu, elapsed = chromium_cpu_seconds() - c0, time.monotonic() - t0
    report(what, elapsed, cpu, before, frame.evaluate(PACING))


def main() -> None:
    """Measure the idle and moving figures in one browser against one server."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--idle-seconds", type=float, default=10.0)
    parser.add_argument("--viewport", default="1366x768")
    args = parser.parse_args()
    width, height = (int(v) for v in args.viewport.split("x"))
    with tempfile.TemporaryDirectory() as root:
        server = LiveServer(Path(root), robot="mujoco", robot_speed=1.0).start()
        try:
            spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0, robot_speed=3.0)
            study_id = open_study(server.url, spec)
            with launch_chromium({"width": width, "height": height}) as context:
                page = context.new_page()
                page.goto(f"{server.url}/study/{study_id}/join?PROLIFIC_PID=idle")
                page.get_by_role("button", name="I agree, continue").click()
                page.get_by_role("button", name="Start").click()
                page.get_by_role("button", name="Begin this task").click()
                token = page.url.rstrip("/").rsplit("/", 1)[-1]
                me = httpx.get(f"{server.url}/api/v1/me", headers={"Authorization": f"Bearer {token}"}).json()
                key = f"{me['participant_id']}/0"
                wait_watching(server, key)
                src = page.locator("#viewer-frame").get_attribute("src") or ""
                box = page.locator("#viewer-frame").bounding_box()
                assert box is not None
                print(f"3D view {box['width']:.0f}x{box['height']:.0f}, address parameters: "
                      f"{src.partition('?')[2] or 'none'}")
                time.sleep(8)
                measure("participant page, 3D view", args.idle_seconds,
                        page.locator("#viewer-frame").element_handle().content_frame())
                page.get_by_role("button", name="2D view").click()
                page.locator("#top-view svg").wait_for()
                time.sleep(3)
                measure("participant page, 2D view", args.idle_seconds)
                page.close()
                size = {"width": int(box["width"]), "height": int(box["height"])}
                objects = iter(OBJECTS)
                for query in ("?fixedDpr=0.5", "?fixedDpr=0.5&pacing=off", "", "?pacing=off"):
                    alone = context.new_page()
                    alone.set_viewport_size(size)
                    alone.goto(f"{server.url}/p/{token}/viewer/{query}")
                    wait_watching(server, key)
                    time.sleep(10)
                    what = f"viewer page alone at {size['width']}x{size['height']}, {query.lstrip('?') or 'paced'}"
                    measure(f"{what}, idle", args.idle_seconds, alone.main_frame)
                    if "fixedDpr" in query:
                        measure_placement(f"{what}, the robot placing an object", server, key, token, next(objects),
                                          alone.main_frame)
                    alone.close()

                # A query's recorded attempt, played by viser's player in the page, then held on its last pose
                # while the participant judges it.
                httpx.post(f"{server.url}/api/v1/me/demonstration/finish",
                           headers={"Authorization": f"Bearer {token}"}, timeout=60).raise_for_status()
                page = context.new_page()
                page.goto(f"{server.url}/p/{token}")
                page.get_by_role("button", name="3D view").click()  # the 2D view was chosen above
                page.get_by_role("button", name="Watch the robot").click()
                page.locator("#viewer-frame").wait_for()
                frame = page.locator("#viewer-frame").element_handle().content_frame()
                page.wait_for_selector("#acceptable", timeout=300_000)
                time.sleep(3)
                measure("participant page, 3D view, a query's attempt played and held", args.idle_seconds, frame)
        finally:
            server.stop()


if __name__ == "__main__":
    main()
