"""The viewer page plays a placement's motion the server sent once (sim/motion_message.py, viewer-motion.js) in
Debian's Chromium: the arm and the object move through the placement on the page's clock, and the view ends where a
freshly loaded view of the same table starts."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tableteach import services
from tests.web.conftest import open_study, study_spec

from joining import join_and_begin
from view_pixels import settled_view, view_pixels

pytestmark = pytest.mark.browser
WAIT_MS = 120_000


def _player(page) -> dict:
    """The motion player's counts in the viewer frame."""
    frame = page.frame_locator("#viewer-frame")
    return frame.locator("body").evaluate("() => window.tableteachMotion && { ...window.tableteachMotion }")


def test_the_page_plays_a_placement_sent_once_and_ends_where_the_server_is(browser_page, slow_mujoco_server) -> None:
    page, server = browser_page, slow_mujoco_server
    study_id = open_study(server.url, study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=0,
                                                 n_tests=0))
    token = join_and_begin(page, server.url, study_id, "motion-1")
    key = f"{services.participant_state(server.ctx, token)['participant_id']}/0"
    deadline = time.monotonic() + WAIT_MS / 1000
    while not server.ctx.robot.view_clients(key):
        assert time.monotonic() < deadline, "the page did not open its 3D view"
        time.sleep(0.1)
    before = settled_view(page)
    assert _player(page) == {"motions": 0, "frames": 0, "cut": 0, "playing": False}

    page.locator('button.object[data-object="bowl"]').click()
    page.wait_for_function("() => document.querySelector('#viewer-frame').contentWindow.tableteachMotion?.motions",
                           timeout=WAIT_MS)
    during = []
    while _player(page)["playing"]:
        during.append(view_pixels(page))
    page.wait_for_selector("#finish:not([disabled])", timeout=WAIT_MS)
    player = _player(page)
    after = settled_view(page)

    # One motion, played frame by frame (software WebGL draws 10 frames a second; the placement lasts seconds).
    assert player["motions"] == 1 and player["cut"] == 0 and not player["playing"]
    assert player["frames"] >= 10, player
    # The view went through poses that are neither the start nor the end.
    assert during, "no view was taken while the motion played"
    assert any(np.abs(v - before).mean() > 0.2 and np.abs(v - after).mean() > 0.2 for v in during)

    # A freshly loaded view of the table (the server's scene, nothing played) looks like where the motion ended.
    page.frame_locator("#viewer-frame").locator("body").evaluate("() => location.reload()")
    page.wait_for_function("() => document.querySelector('#viewer-frame').contentWindow.tableteachMotion",
                           timeout=WAIT_MS)
    reloaded = settled_view(page)
    assert _player(page)["motions"] == 0
    same, moved = np.abs(after - reloaded).mean(), np.abs(before - reloaded).mean()
    assert same < 0.2 * moved, (same, moved)
