"""Participant page speed in real Chromium on an idle server: click-to-panel latency, load to 3D view, idle tab CPU.

    .venv/bin/python benchmarks/bench_participant.py [--clicks 20] [--viewport 1366x768] [--idle-seconds 10]

- click to panel: a placement arrives at the server (POST /me/placements, the same service call a click in
  the 3D view makes) and the page's side panel shows the robot busy, then the object on Table B; times
  from the request to the panel's DOM change (MutationObserver, same machine clock), median and p95.
- click in the 3D view to panel (--view-clicks): the pointer is moved onto an object on Table A (projected through
  the browser's camera, as tests/browser/test_participant.py clicks), rests 0.4 s, clicks; times from the click to
  the panel showing the robot busy (the click reached the server through viser's websocket). A click that shows
  nothing within 15 s is counted as missed and tried again.
- load to 3D view: from navigation start of /p/{token} (at a demonstration) until viser's client in the
  frame has connected through the proxy and reported its camera (the server counts it as watching).
- longest stall: the longest pause of a 100 ms timer on the page's main thread (which the 3D view's frame
  shares) from the reload on, through the idle stretch and the placements; the page switches to 2D after two
  stalls of 5 s within a minute (frontend/participant-view-mode.js).
- idle tab CPU: over a quiet stretch with the 3D view shown and nothing moving, as a share of one core: the
  CPU time of every Chromium process this benchmark started (/proc: the renderer, and the GPU process, which
  does the software WebGL drawing), and Chromium's own Performance.getMetrics TaskDuration (the renderer's
  main thread busy, including its waits on the GPU process).
Uses /usr/bin/chromium (software WebGL on a machine without a GPU) and the MuJoCo robot.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "browser"))

import httpx  # noqa: E402
import numpy as np  # noqa: E402

from conftest import LiveServer, launch_chromium  # noqa: E402
from scene_clicks import project, wait_for_camera  # noqa: E402
from tests.web.conftest import open_study, study_spec  # noqa: E402

STALLS = """(() => { if (window !== window.top) return; window.longestStall = 0; let last = performance.now();
  setInterval(() => { const now = performance.now(); window.longestStall = Math.max(window.longestStall, now - last);
    last = now; }, 100); })();"""
OBJECTS = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]
VIEW_OBJECTS = OBJECTS[:3]  # large enough that a click projected to the centre lands on them (the cutlery is thin)
WATCH_PANEL = """(name) => {
  window.panelSeen = null;  // {busy, placed}: when the panel first showed the robot busy, then the object placed
  let busy = null;
  new MutationObserver((_, observer) => {
    const status = document.querySelector('#status');
    if (busy === null && status && status.classList.contains('busy')) busy = Date.now();
    const placed = document.querySelector('.placed');
    if (placed && placed.textContent.includes(name)) {
      window.panelSeen = { busy, placed: Date.now() };
      observer.disconnect();
    }
  }).observe(document.getElementById('panel'), { subtree: true, childList: true, characterData: true,
    attributes: true });
}"""


def chromium_cpu_seconds() -> float:
    """CPU seconds (user + system) used so far by the Chromium processes below this one (Linux /proc)."""
    parents: dict[int, int] = {}
    ticks: dict[int, int] = {}
    names: dict[int, str] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="utf-8") as f:
                stat = f.read()
        except OSError:
            continue  # the process ended meanwhile
        pid, rest = int(entry), stat[stat.rindex(")") + 2:].split()
        names[pid] = stat[stat.index("(") + 1:stat.rindex(")")]
        parents[pid], ticks[pid] = int(rest[1]), int(rest[11]) + int(rest[12])
    children: dict[int, list[int]] = {}
    for pid, parent in parents.items():
        children.setdefault(parent, []).append(pid)
    below, stack = set(), [os.getpid()]
    while stack:
        for child in children.get(stack.pop(), []):
            if child not in below:
                below.add(child)
                stack.append(child)
    return sum(ticks[p] for p in below if "chrom" in names[p]) / os.sysconf("SC_CLK_TCK")


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0..1) by linear interpolation."""
    ordered = sorted(values)
    k = (len(ordered) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(ordered) - 1)
    return ordered[lo] + (ordered[hi] - ordered[lo]) * (k - lo)


def wait_watching(server: LiveServer, key: str, timeout: float = 120.0) -> float:
    """Wall-clock time (time.time) at which a browser first watches the table's view."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        activity = server.ctx.robot.activity(key)
        if activity is not None and activity.watchers > 0:
            return time.time()
        time.sleep(0.01)
    raise TimeoutError(f"no browser watched table {key} within {timeout} s")


def click_in_view(page: Any, server: LiveServer, key: str, obj: str) -> float | None:
    """Click an object in the page's 3D view; seconds from the click to the panel showing the robot busy (None
    if it did not within 15 s)."""
    robot = server.ctx.robot
    world = robot.scene(key)
    if world is None:  # an untouched table has no simulation yet: the same start, rebuilt
        robot.restore(key, [])
        world = robot.scene(key)
    camera = wait_for_camera(lambda: robot.view_clients(key))
    page.evaluate("() => window.scrollTo(0, 0)")
    box = page.frame_locator("#viewer-frame").locator("canvas").first.bounding_box()
    geoms = np.flatnonzero(world.model.geom_bodyid == world.layout.body[obj])
    point = world.data.geom_xpos[geoms].mean(axis=0) + np.array([0.0, 0.0, 0.01])
    x, y = project(camera, point, box["width"], box["height"])
    page.mouse.move(box["x"] + x, box["y"] + y)
    time.sleep(0.4)
    page.evaluate(WATCH_PANEL, obj.replace("_", " "))
    clicked = time.time()
    page.mouse.click(box["x"] + x, box["y"] + y)
    try:
        page.wait_for_function("() => window.panelSeen !== null", timeout=15_000)
    except Exception:
        return None
    seen = page.evaluate("() => window.panelSeen")
    return (seen["busy"] or seen["placed"]) / 1000 - clicked


def main() -> None:
    """Run the three measurements and print them."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--clicks", type=int, default=20)
    parser.add_argument("--view-clicks", type=int, default=3, help="clicks in the 3D view (at most 3)")
    parser.add_argument("--viewport", default="1366x768")
    parser.add_argument("--idle-seconds", type=float, default=10.0)
    parser.add_argument("--settle-seconds", type=float, default=10.0, help="after the load, before the idle stretch")
    parser.add_argument("--robot-speed", type=float, default=8.0, help="server playback speed (motion between clicks)")
    args = parser.parse_args()
    width, height = (int(v) for v in args.viewport.split("x"))
    demos = -(-args.clicks // len(OBJECTS)) + (1 if args.view_clicks else 0)
    with tempfile.TemporaryDirectory() as root:
        server = LiveServer(Path(root), robot="mujoco", robot_speed=args.robot_speed).start()
        try:
            spec = study_spec(["active"], n_practice=0, n_demonstrations=demos, n_queries=1, n_tests=0)
            study_id = open_study(server.url, spec)
            with launch_chromium({"width": width, "height": height}) as context:
                page = context.new_page()
                page.add_init_script(STALLS)
                page.goto(f"{server.url}/study/{study_id}/join?PROLIFIC_PID=bench")
                token = page.url.rstrip("/").rsplit("/", 1)[-1]
                headers = {"Authorization": f"Bearer {token}"}
                page.get_by_role("button", name="I agree, continue").click()
                page.get_by_role("button", name="Start").click()
                page.get_by_role("button", name="Begin this task").click()
                pid = httpx.get(f"{server.url}/api/v1/me", headers=headers).json()["participant_id"]
                key = f"{pid}/0"
                wait_watching(server, key)

                # Load to interactive 3D view: a fresh load of the page at the demonstration.
                page.reload()
                started = page.evaluate("() => performance.timeOrigin") / 1000
                time.sleep(0.2)
                watching = wait_watching(server, key)
                load_seconds = watching - started

                # Idle tab CPU: nothing moves, the view is shown (and has drawn its first frames).
                time.sleep(args.settle_seconds)
                cdp = context.new_cdp_session(page)
                cdp.send("Performance.enable")

                def task_seconds() -> float:
                    metrics = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
                    return float(metrics["TaskDuration"])

                t0, c0, p0 = time.monotonic(), task_seconds(), chromium_cpu_seconds()
                time.sleep(args.idle_seconds)
                elapsed = time.monotonic() - t0
                idle_share = (task_seconds() - c0) / elapsed
                idle_cpu = (chromium_cpu_seconds() - p0) / elapsed

                clicks, missed = [], 0
                for obj in VIEW_OBJECTS[:args.view_clicks]:
                    for _ in range(3):
                        took = click_in_view(page, server, key, obj)
                        if took is not None:
                            clicks.append(took)
                            break
                        missed += 1
                    page.wait_for_selector("#status:not(.busy)", timeout=60_000)
                    time.sleep(0.3)
                if args.view_clicks:
                    httpx.post(f"{server.url}/api/v1/me/demonstration/finish", headers=headers).raise_for_status()
                    page.wait_for_function("() => !document.querySelector('.placed')?.textContent.includes('fork')")
                    wait_watching(server, f"{pid}/0")

                busy, placed = [], []
                for i in range(args.clicks):
                    obj = OBJECTS[i % len(OBJECTS)]
                    page.evaluate(WATCH_PANEL, obj.replace("_", " "))
                    sent = time.time()
                    r = httpx.post(f"{server.url}/api/v1/me/placements", json={"object": obj}, headers=headers,
                                   timeout=30)
                    r.raise_for_status()
                    page.wait_for_function("() => window.panelSeen !== null", timeout=30_000)
                    seen = page.evaluate("() => window.panelSeen")
                    placed.append(seen["placed"] / 1000 - sent)
                    if seen["busy"] is not None:
                        busy.append(seen["busy"] / 1000 - sent)
                    # Wait until the robot is still (the next placement starts from a quiet server).
                    page.wait_for_selector("#status:not(.busy)", timeout=60_000)
                    if obj == OBJECTS[-1]:
                        httpx.post(f"{server.url}/api/v1/me/demonstration/finish", headers=headers).raise_for_status()
                        page.wait_for_function("() => !document.querySelector('.placed')?.textContent.includes('fork')")
                    time.sleep(0.3)
                longest_stall = page.evaluate("() => window.longestStall") / 1000
        finally:
            server.stop()

    ms = [1000 * v for v in placed]
    print(f"viewport {args.viewport}, robot speed {args.robot_speed}x, {len(ms)} placements")
    print(f"placement request -> panel shows the object: median {statistics.median(ms):.0f} ms, "
          f"p95 {percentile(ms, 0.95):.0f} ms, max {max(ms):.0f} ms")
    if busy:
        bms = [1000 * v for v in busy]
        print(f"placement request -> panel shows the robot busy ({len(bms)} seen): median {statistics.median(bms):.0f} "
              f"ms, p95 {percentile(bms, 0.95):.0f} ms")
    if clicks:
        cms = [1000 * v for v in clicks]
        print(f"click in the 3D view -> panel shows the robot busy ({len(cms)} clicks, {missed} missed): median "
              f"{statistics.median(cms):.0f} ms, max {max(cms):.0f} ms")
    print(f"page load -> 3D view connected and watching: {load_seconds:.2f} s")
    print(f"longest stall of the page's main thread from the load on: {longest_stall:.1f} s")
    print(f"idle participant tab (3D view shown, nothing moving), over {args.idle_seconds:.0f} s: "
          f"{100 * idle_cpu:.1f}% of one core (CPU of all Chromium processes), "
          f"{100 * idle_share:.1f}% (renderer main thread busy, Chromium TaskDuration)")


if __name__ == "__main__":
    main()
