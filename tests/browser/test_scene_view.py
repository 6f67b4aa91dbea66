"""Headless Chromium loads a participant's viser view, clicks an object, and the robot places it."""

from __future__ import annotations

import queue
import time

import numpy as np
import pytest
import viser.transforms as vtf

from tableteach.sim.session import SceneSession

pytestmark = pytest.mark.browser


def _wait_for_camera(session: SceneSession, timeout: float = 60.0) -> object:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for client in session.view.server.get_clients().values():
            try:
                client.camera.fov  # raises until the browser has reported its camera
                return client.camera
            except AssertionError:
                pass
        time.sleep(0.1)
    raise TimeoutError(f"no browser camera reported within {timeout} s: expected the page to connect")


def _project(camera, point: np.ndarray, width: float, height: float) -> tuple[float, float]:
    """Pixel of a world point in the client's canvas (viser cameras follow OpenCV: +z ahead, +y down)."""
    rotation = vtf.SO3(np.asarray(camera.wxyz)).as_matrix()
    local = rotation.T @ (point - np.asarray(camera.position))
    assert local[2] > 0, "point is behind the camera"
    focal = (height / 2) / np.tan(camera.fov / 2)
    return width / 2 + focal * local[0] / local[2], height / 2 + focal * local[1] / local[2]


def _click_object(page, session: SceneSession, camera, obj: str) -> None:
    box = page.locator("canvas").first.bounding_box()
    layout, data = session.world.layout, session.world.data
    centre = data.xpos[layout.body[obj]] + np.array([0.0, 0.0, 0.03])  # inside the bowl's wall height
    x, y = _project(camera, centre, box["width"], box["height"])
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
        camera = _wait_for_camera(session)
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
