"""Headless Chromium loads a participant's viser view, clicks an object, and the robot places it."""

from __future__ import annotations

import queue
import time

import numpy as np
import pytest

from tableteach.sim.session import SceneSession
from tests.waiting import WAIT_SECONDS

from scene_clicks import project, wait_for_camera

pytestmark = pytest.mark.browser
RECLICK_SECONDS = 5.0  # software WebGL on a busy machine: a click before the hover raycast has run can miss


def _click_object(page, session: SceneSession, camera, obj: str) -> None:
    box = page.locator("canvas").first.bounding_box()
    layout, data = session.world.layout, session.world.data
    lift = 0.03 if obj == "bowl" else 0.01  # inside the bowl's wall height; just above a plate
    centre = data.xpos[layout.body[obj]] + np.array([0.0, 0.0, lift])
    x, y = project(camera, centre, box["width"], box["height"])
    page.mouse.move(box["x"] + x, box["y"] + y)
    time.sleep(0.5)  # give the hover raycast a chance before pressing (a click that misses is made again)
    page.mouse.click(box["x"] + x, box["y"] + y)


def _click_until_reported(page, session: SceneSession, camera, obj: str, clicks: queue.Queue[str]) -> str:
    """Click the object until the view reports a click (the first one reported), within the generous limit."""
    deadline = time.monotonic() + WAIT_SECONDS
    while time.monotonic() < deadline:
        _click_object(page, session, camera, obj)
        try:
            return clicks.get(timeout=RECLICK_SECONDS)
        except queue.Empty:
            continue
    raise AssertionError(f"clicking the {obj} in the 3D view was never reported within {WAIT_SECONDS:.0f} s")


def test_click_an_object_then_the_robot_places_it(browser_page):
    clicks: queue.Queue[str] = queue.Queue()
    session = SceneSession(seed=0, view=True, on_click=clicks.put, realtime=True, speed=8.0)
    try:
        page = browser_page
        page.goto(session.view.url)
        page.wait_for_selector("canvas")
        camera = wait_for_camera(session.view.server)
        assert _click_until_reported(page, session, camera, "bowl", clicks) == "bowl"

        session.run(["bowl"])  # a browser is connected, so this replays in (sped-up) real time
        assert session.wait(timeout=WAIT_SECONDS) == [frozenset(), frozenset({"bowl"})]
        assert session.labels() == {"bowl"}
        assert "bowl" not in session.view.clickable

        # The placed bowl no longer reports clicks: after clicking it, the next click reported is the plate's.
        while not clicks.empty():  # extra clicks on the bowl made before its first one was reported
            assert clicks.get_nowait() == "bowl"
        _click_object(page, session, camera, "bowl")
        assert _click_until_reported(page, session, camera, "dinner_plate", clicks) == "dinner_plate"
    finally:
        session.close()
