"""Idle CPU of the participant page's views in real Chromium: 3D (viser's client, software WebGL), 2D, and viser's
viewer page alone at the frame's size with and without fixedDpr=0.5.

    .venv/bin/python benchmarks/bench_view_idle.py [--idle-seconds 10] [--viewport 1366x768]

Each figure is the CPU time of every Chromium process this benchmark started (/proc, as bench_participant.py
counts it) over a quiet stretch of a demonstration screen, as a share of one core.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "browser"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import httpx  # noqa: E402

from bench_participant import chromium_cpu_seconds, wait_watching  # noqa: E402
from conftest import LiveServer, launch_chromium  # noqa: E402
from tests.web.conftest import open_study, study_spec  # noqa: E402


def measure(what: str, seconds: float) -> None:
    """Print the Chromium processes' CPU share over the next `seconds`."""
    c0, t0 = chromium_cpu_seconds(), time.monotonic()
    time.sleep(seconds)
    share = (chromium_cpu_seconds() - c0) / (time.monotonic() - t0)
    print(f"{what}: {100 * share:.1f}% of one core over {seconds:.0f} s", flush=True)


def main() -> None:
    """Measure the four idle figures in one browser against one server."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--idle-seconds", type=float, default=10.0)
    parser.add_argument("--viewport", default="1366x768")
    args = parser.parse_args()
    width, height = (int(v) for v in args.viewport.split("x"))
    with tempfile.TemporaryDirectory() as root:
        server = LiveServer(Path(root), robot="mujoco", robot_speed=8.0).start()
        try:
            spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
            study_id = open_study(server.url, spec)
            with launch_chromium({"width": width, "height": height}) as context:
                page = context.new_page()
                page.goto(f"{server.url}/study/{study_id}/join?PROLIFIC_PID=idle")
                page.get_by_role("button", name="I agree, continue").click()
                page.get_by_role("button", name="Start").click()
                page.get_by_role("button", name="Begin this task").click()
                token = page.url.rstrip("/").rsplit("/", 1)[-1]
                me = httpx.get(f"{server.url}/api/v1/me", headers={"Authorization": f"Bearer {token}"}).json()
                wait_watching(server, f"{me['participant_id']}/0")
                src = page.locator("#viewer-frame").get_attribute("src") or ""
                box = page.locator("#viewer-frame").bounding_box()
                assert box is not None
                print(f"3D view {box['width']:.0f}x{box['height']:.0f}, address parameters: "
                      f"{src.partition('?')[2] or 'none'}")
                time.sleep(8)
                measure("participant page, 3D view", args.idle_seconds)
                page.get_by_role("button", name="2D view").click()
                page.locator("#top-view svg").wait_for()
                time.sleep(3)
                measure("participant page, 2D view", args.idle_seconds)
                page.close()
                size = {"width": int(box["width"]), "height": int(box["height"])}
                for query in ("?fixedDpr=0.5", ""):
                    alone = context.new_page()
                    alone.set_viewport_size(size)
                    alone.goto(f"{server.url}/p/{token}/viewer/{query}")
                    time.sleep(10)
                    measure(f"viewer page alone at {size['width']}x{size['height']}, {query or 'no fixedDpr'}",
                            args.idle_seconds)
                    alone.close()
        finally:
            server.stop()


if __name__ == "__main__":
    main()
