"""Headless Chromium loads a participant's viser view, clicks an object, and the robot places it."""

from __future__ import annotations

import queue
import time

import numpy as np
import pytest

from tableteach.sim.session import SceneSession

from scene_clicks import project, wait_for_camera

pytestmark = pytest.mark.browser


def _click_object(page, session: SceneSession, camera, obj: str) -> None:
    box = page.locator("canvas").first.bounding_box()
    layout, data = session.world.layout, session.world.data
    centre = data.xpos[layout.body[obj]] + np.array([0.0, 0.0, 0.03])  # inside the bowl's wall height
    x, y = project(camera, centre, box["width"], box["height"])
    page.mouse.move(box["x"] + x, box["y"] + y)
    time.sleep(0.5)  # let the hover raycast run before pressing
    page.mouse.click(box["x"] + x, box["y"] + y)


def test_click_an_object_then_the_robot_places_it(browser_page):
    clicks: queue.Queue[str] = queue.Queue()
    session = SceneSession(seed=0, view=True, on_click=clicks.put, realtime=True, speed=8.0)
    try:
        page = browser_page
        page.goto(session.view.url)
        page.wait_for_selector("canvas")
        camera = wait_for_camera(session.view.server)
        time.sleep(3.0)  # software WebGL: let the scene's first frames draw
        _click_object(page, session, camera, "bowl")
        assert clicks.get(timeout=30) == "bowl"

        session.run(["bowl"])  # a browser is connected, so this replays in (sped-up) real time
        assert session.wait(timeout=60) == [frozenset(), frozenset({"bowl"})]
        assert session.labels() == {"bowl"}
        assert "bowl" not in session.view.clickable

        # The placed bowl no longer reports clicks.
        _click_object(page, session, camera, "bowl")
        with pytest.raises(queue.Empty):
            clicks.get(timeout=3)
    finally:
        session.close()
