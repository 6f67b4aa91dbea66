"""The participant's copy of viser's client (frontend/viewer-pacing.js) draws only when something changes: viser's
heartbeat is recognised and slowed, no frame is drawn while nothing moves, and frames come while the robot moves."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from tests.waiting import wait_until
from tests.web.conftest import open_study, study_spec

from joining import join_and_begin

pytestmark = pytest.mark.browser
PACING = "() => ({ ...window.tableteachPacing })"


def _still_for_three_beats(frame: Any) -> bool:
    """Whether the view drew nothing while three of viser's heartbeats were skipped."""
    before = frame.evaluate(PACING)
    wait_until(lambda: frame.evaluate(PACING)["skipped"] >= before["skipped"] + 3, "three skipped heartbeats")
    return frame.evaluate(PACING)["frames"] == before["frames"]


def test_the_3d_view_draws_nothing_while_idle_and_draws_while_the_robot_moves(browser_page, mujoco_server):
    server, page = mujoco_server, browser_page
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0)
    study_id = open_study(server.url, spec)
    token = join_and_begin(page, server.url, study_id, "pacing")
    headers = {"Authorization": f"Bearer {token}"}
    pid = httpx.get(f"{server.url}/api/v1/me", headers=headers).json()["participant_id"]
    key = f"{pid}/0"
    wait_until(lambda: (a := server.ctx.robot.activity(key)) is not None and a.watchers > 0, "the 3D view to connect")
    frame = page.locator("#viewer-frame").element_handle().content_frame()
    assert frame is not None and "tableteach-pacing" in frame.content()

    # Once the scene has loaded (a slow software renderer may take a while), the view stops drawing.
    wait_until(lambda: _still_for_three_beats(frame), "the 3D view to stop drawing while nothing moves", timeout=300)
    idle = frame.evaluate(PACING)
    assert idle["heartbeats"] >= 1  # recognised: it ran, and its later beats were skipped

    assert httpx.post(f"{server.url}/api/v1/me/placements", json={"object": "bowl"}, headers=headers,
                      timeout=60).status_code == 200
    wait_until(lambda: frame.evaluate(PACING)["frames"] > idle["frames"], "frames while the robot moves")
    page.wait_for_function("() => document.querySelector('.placed')?.textContent.includes('bowl')", timeout=120_000)
    page.wait_for_selector("#status:not(.busy)", timeout=120_000)
    wait_until(lambda: _still_for_three_beats(frame), "the 3D view to stop drawing once the robot is still",
               timeout=300)
