"""The answer to a robot's attempt waits for the attempt to be shown to the end, in headless Chromium with the
MuJoCo robot: a 3D player that was read part-way and then went quiet (its frame emptied, as a reload or a stalled
page leaves it) holds the answer and is loaded again, instead of letting the participant judge half a motion."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from pathlib import Path

import pytest

from tableteach.client import ExperimenterClient
from tests.waiting import wait_until
from tests.web.conftest import EXPERIMENTER_TOKEN, open_study, study_spec

from conftest import TIMEOUT_MS, LiveServer
from joining import join_and_begin

pytestmark = pytest.mark.browser


def _assessment(url: str, study_id: str) -> dict[str, str] | None:
    exp = ExperimenterClient(url, token=EXPERIMENTER_TOKEN)
    try:
        events = list(csv.DictReader(io.StringIO(exp.export(study_id, "events"))))
    finally:
        exp.close()
    return next((e for e in events if e["kind"] == "assessment"), None)


@pytest.fixture
def real_time_mujoco_server(tmp_path: Path) -> Iterator[LiveServer]:
    """The app with the MuJoCo robot at real speed: its attempt plays long enough to be interrupted part-way even
    when a loaded machine holds the page up for seconds."""
    server = LiveServer(tmp_path, robot="mujoco", robot_speed=1.0).start()
    try:
        yield server
    finally:
        server.stop()


def test_a_player_that_goes_quiet_part_way_holds_the_answer_and_is_loaded_again(browser_page,
                                                                                 real_time_mujoco_server):
    mujoco_server = real_time_mujoco_server
    page = browser_page  # the 3D view, chosen
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    study_id = open_study(mujoco_server.url, spec)
    join_and_begin(page, mujoco_server.url, study_id, "gate-1")
    for obj in ("dinner_plate", "bowl"):
        page.wait_for_selector("#finish:not([disabled])", timeout=TIMEOUT_MS)
        page.locator(f'button.object[data-object="{obj}"]').click()
    page.wait_for_selector("#finish:not([disabled])", timeout=TIMEOUT_MS)
    page.get_by_role("button", name="Finish demonstration").click()
    page.wait_for_function("() => document.getElementById('finish-anyway') || document.getElementById('start')")
    if page.locator("#finish-anyway").count():
        page.locator("#finish-anyway").click()

    page.get_by_role("button", name="Watch the robot").click()
    # The page has read part of it from the player (the fraction it keeps on the view's box).
    page.wait_for_function("() => Number(document.getElementById('viewer').dataset.shownFraction) > 0",
                           timeout=TIMEOUT_MS)
    playback = page.locator("#viewer-frame").get_attribute("src")
    assert "playbackPath=" in playback
    # The player goes quiet part-way: nothing in the frame can say how far it got.
    shown = page.evaluate("() => { document.getElementById('viewer-frame').src = 'about:blank';"
                          " return Number(document.getElementById('viewer').dataset.shownFraction); }")
    assert 0 < shown < 1, f"the attempt was {shown:.0%} shown when its player was emptied: expected part of it"
    # The page loads the player again (the same recording, from the start) rather than giving up on it ...
    page.wait_for_function("(src) => document.getElementById('viewer-frame').getAttribute('src') === src",
                           arg=playback, timeout=2 * TIMEOUT_MS)
    assert page.locator("#acceptable").is_disabled()
    # ... and the answer waits until that player has shown the attempt to its end.
    page.wait_for_selector("#acceptable:not([disabled])", timeout=2 * TIMEOUT_MS)
    page.locator("#acceptable").click()
    assessment = wait_until(lambda: _assessment(mujoco_server.url, study_id), "the verdict to be recorded")
    assert '"shown_fraction":1' in assessment["payload"]
