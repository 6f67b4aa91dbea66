"""A robot execution is watched by playing its recorded .viser file in viser's own client: the scene moves
while the execution runs and then holds still on the final table (it does not start over by itself)."""

from __future__ import annotations

import io
import time

import httpx
import numpy as np
import pytest
from PIL import Image

from tests.browser.conftest import LiveServer
from tests.waiting import wait_until
from tests.web.conftest import open_study, study_spec

pytestmark = pytest.mark.browser
STILL_SECONDS = 2.0  # two screenshots this far apart that do not differ: the scene holds still
NEXT_FRAMES = "() => new Promise(done => requestAnimationFrame(() => requestAnimationFrame(done)))"


def _shot(page) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(page.locator("canvas").first.screenshot())).convert("L"), dtype=float)


def _changed(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels whose brightness changed noticeably."""
    return float(np.mean(np.abs(a - b) > 12))


@pytest.fixture
def slow_motion_server(tmp_path):
    """The app with the MuJoCo robot in slow motion (an action takes about 16 s): software WebGL in a busy
    machine can take seconds to draw the first frame, and viser's player keeps to the wall clock meanwhile."""
    server = LiveServer(tmp_path, robot="mujoco", robot_speed=0.35).start()
    try:
        yield server
    finally:
        server.stop()


def test_the_browser_plays_the_recorded_execution_then_holds_the_final_table(browser_page, slow_motion_server):
    server, page = slow_motion_server, browser_page
    study_id = open_study(server.url, study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1,
                                                 n_tests=0))
    joined = httpx.post(f"{server.url}/api/v1/studies/{study_id}/join", json={"prolific_pid": "playback"}).json()
    headers = {"Authorization": f"Bearer {joined['state']['token']}"}

    def post(path: str, body: dict | None = None) -> dict:
        answer = httpx.post(f"{server.url}/api/v1{path}", json=body, headers=headers, timeout=60)
        assert answer.status_code == 200, answer.text
        return answer.json()

    post("/me/consent", {"agree": True, "consent_version": joined["state"]["consent"]["version"]})
    post("/me/instructions")
    post("/me/placements", {"object": "dinner_plate"})
    post("/me/demonstration/finish")
    before = post("/me/view")
    assert "playbackPath" not in (before["url"] or "")  # no execution yet: the live view
    running = post("/me/execution")["execution"]
    assert running["status"] == "running" and len(running["events"]) >= 2
    view = post("/me/view")
    assert view["available"] and "playbackPath=" in view["url"]

    with page.expect_response(lambda r: r.url.endswith(".viser")) as recording:
        page.goto(f"{server.url}{view['url']}")
    assert recording.value.status == 200 and len(recording.value.body()) > 10_000
    page.wait_for_selector("canvas")
    # drawn: not one uniform colour any more
    wait_until(lambda: (shot := _shot(page)).max() > shot.min(), "software WebGL to draw the scene", interval=0.5)
    first = _shot(page)
    wait_until(lambda: _changed(first, _shot(page)) > 0.002, "the scene to move while the recording plays",
               interval=0.5)

    wait_until(lambda: httpx.get(f"{server.url}/api/v1/me", headers=headers, timeout=60).json()["execution"][
        "status"] == "finished", "the execution to finish", timeout=120, interval=0.2)
    # The page started playing a moment after the execution's clock: it holds still once it has caught up,
    # and stays so (it does not start over by itself).
    shots = [_shot(page)]

    def held_still() -> bool:
        time.sleep(STILL_SECONDS)
        shots.append(_shot(page))
        return _changed(shots[-2], shots[-1]) < 0.001

    wait_until(held_still, "the finished execution to hold still", interval=0)
    time.sleep(STILL_SECONDS)
    assert _changed(shots[-1], _shot(page)) < 0.001, "the finished execution started moving again"

    # The participant's copy of the player shows no controls: no playback bar (pause, time, speed, scene tree),
    # no control panel, no token, at a laptop's and a phone's size.
    token = joined["state"]["token"]
    for size in ({"width": 1366, "height": 768}, {"width": 390, "height": 844}):
        page.set_viewport_size(size)
        page.wait_for_function("w => window.innerWidth === w", arg=size["width"])
        page.evaluate(NEXT_FRAMES)  # the player's layout has followed the new size
        papers = page.evaluate("() => [...document.querySelectorAll('.mantine-Paper-root')]"
                               ".map(e => e.getClientRects().length > 0)")
        assert papers and not any(papers), f"viser's controls show at {size}: {papers}"
        text = page.evaluate("() => document.body.innerText")
        assert token not in text and "Dev Settings" not in text
        assert not page.get_by_label("Show scene tree").first.is_visible()
