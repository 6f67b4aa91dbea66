"""The participant page's 2D view in headless Chromium with the MuJoCo robot: a browser without WebGL lands on it,
demonstrates by clicking the objects drawn from above, watches a query play in 2D (which unlocks the answer) and
answers; axe-core on the 2D view at 1366x768 and 390x844; the participant's 2D/3D switch."""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import pytest

from tableteach.client import ExperimenterClient
from tests.waiting import wait_until
from tests.web.conftest import EXPERIMENTER_TOKEN, open_study, study_spec

from accessibility import assert_accessible
from conftest import CHROMIUM, NO_WEBGL_ARGS, TIMEOUT_MS, launch_chromium
from joining import join_and_begin

pytestmark = pytest.mark.browser

SHOTS = None if not os.environ.get("TABLETEACH_SHOTS") else Path(os.environ["TABLETEACH_SHOTS"])
LAPTOP = {"width": 1366, "height": 768}
PHONE = {"width": 390, "height": 844}


def _events(url: str, study_id: str) -> list[dict[str, str]]:
    exp = ExperimenterClient(url, token=EXPERIMENTER_TOKEN)
    try:
        return list(csv.DictReader(io.StringIO(exp.export(study_id, "events"))))
    finally:
        exp.close()


def _placed_text(page) -> str:
    return page.locator(".placed").first.inner_text()


# Draws the robot's hand and arm over the bowl, reads which object a click at the bowl's centre reaches, then
# puts the robot back as it was.
ROBOT_OVER_THE_BOWL = """() => {
  const svg = document.querySelector('#top-view svg');
  const hand = svg.querySelector('.robot-hand'), arm = svg.querySelector('.robot-arm');
  const box = svg.querySelector('.object-bowl').getBoundingClientRect();
  const [sx, sy] = [box.left + box.width / 2, box.top + box.height / 2];
  const at = new DOMPoint(sx, sy).matrixTransform(svg.getScreenCTM().inverse());
  const saved = [hand.getAttribute('cx'), hand.getAttribute('cy'), hand.style.display, arm.getAttribute('points'),
    arm.style.display];
  hand.setAttribute('cx', at.x); hand.setAttribute('cy', at.y); hand.style.display = '';
  arm.setAttribute('points', `${at.x - 60},${at.y} ${at.x + 60},${at.y}`); arm.style.display = '';
  const reached = document.elementFromPoint(sx, sy)?.closest('.object')?.dataset.object ?? null;
  hand.setAttribute('cx', saved[0]); hand.setAttribute('cy', saved[1]); hand.style.display = saved[2];
  arm.setAttribute('points', saved[3]); arm.style.display = saved[4];
  return reached;
}"""


def test_without_webgl_a_participant_demonstrates_watches_and_answers_in_the_2d_view(mujoco_server):
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} not found")
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    study_id = open_study(mujoco_server.url, spec)
    with launch_chromium(LAPTOP, NO_WEBGL_ARGS) as context:
        page = context.new_page()
        join_and_begin(page, mujoco_server.url, study_id, "flat-1")
        assert page.evaluate("() => !document.createElement('canvas').getContext('webgl')")  # really no WebGL
        page.locator("#top-view svg .object-bowl").wait_for()
        frame = page.locator("#viewer-frame")
        assert not frame.is_visible() and frame.get_attribute("src") is None
        assert page.get_by_role("button", name="2D view").get_attribute("aria-pressed") == "true"
        assert page.get_by_role("button", name="3D view").is_disabled()
        assert "cannot show 3D" in page.locator("#view-mode-note").inner_text()
        assert "in the 2D view" in page.locator("#status").inner_text()
        labels = page.eval_on_selector_all("#top-view [data-label] text", "nodes => nodes.map((n) => n.textContent)")
        assert {"dinner plate", "small plate", "bowl", "knife", "fork", "Table A", "Table B"} <= set(labels)
        assert page.evaluate(ROBOT_OVER_THE_BOWL) == "bowl"  # the arm passing over an object never takes its click
        page.screenshot(path=str(SHOTS / "demo-laptop.png")) if SHOTS else None
        assert_accessible(page, "demonstration in the 2D view (1366x768)")
        page.set_viewport_size(PHONE)
        page.locator("#view-2d").scroll_into_view_if_needed()
        assert page.locator("#top-view svg").is_visible()
        page.screenshot(path=str(SHOTS / "demo-phone.png")) if SHOTS else None
        assert_accessible(page, "demonstration in the 2D view (390x844)")
        page.set_viewport_size(LAPTOP)

        # Demonstrate by clicking the objects in the picture (Table A), one after the other.
        for obj, name in (("dinner_plate", "dinner plate"), ("bowl", "bowl")):
            page.wait_for_selector("#finish:not([disabled])")
            page.locator(f"#top-view svg .object-{obj}").click()
            page.wait_for_function("(n) => document.querySelector('.placed')?.textContent.includes(n)", arg=name)
        page.wait_for_selector("#finish:not([disabled])")
        page.get_by_role("button", name="Finish demonstration").click()
        page.wait_for_function("() => document.getElementById('finish-anyway') || document.getElementById('start')")
        if page.locator("#finish-anyway").count():  # the task asks for more objects: finish anyway
            page.locator("#finish-anyway").click()

        # The query plays in 2D; its answer unlocks only once the 2D view has played it to the end.
        page.get_by_role("button", name="Watch the robot").click()
        page.wait_for_function("() => document.querySelector('#top-view .robot-hand')?.style.display === ''",
                               timeout=TIMEOUT_MS)
        page.wait_for_selector("#acceptable:not([disabled])", timeout=3 * TIMEOUT_MS)
        page.screenshot(path=str(SHOTS / "answer-laptop.png")) if SHOTS else None
        assert_accessible(page, "the robot's attempt in the 2D view (1366x768)")
        page.set_viewport_size(PHONE)
        page.screenshot(path=str(SHOTS / "answer-phone.png")) if SHOTS else None
        assert_accessible(page, "the robot's attempt in the 2D view (390x844)")
        page.set_viewport_size(LAPTOP)
        page.locator("#acceptable").click()
        assessment = wait_until(lambda: next((e for e in _events(mujoco_server.url, study_id)
                                              if e["kind"] == "assessment"), None), "the verdict to be recorded")
        page.screenshot(path=str(SHOTS / "after.png")) if SHOTS else None
        page.close()
    assert '"shown_fraction":1' in assessment["payload"]  # the 2D view showed the attempt to the end


def test_the_participant_switches_between_the_3d_and_the_2d_view_and_the_choice_is_kept(default_view_page,
                                                                                        mujoco_server):
    page = default_view_page
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    study_id = open_study(mujoco_server.url, spec)
    join_and_begin(page, mujoco_server.url, study_id, "switch-1")
    page.wait_for_function("() => document.getElementById('viewer-frame').getAttribute('src')")
    src = page.locator("#viewer-frame").get_attribute("src")
    assert "fixedDpr=0.5" in src  # software WebGL here: the 3D view is drawn at half resolution
    assert page.get_by_role("button", name="3D view").get_attribute("aria-pressed") == "true"

    page.get_by_role("button", name="2D view").click()
    page.locator("#top-view svg .object-fork").wait_for()
    assert page.locator("#viewer-frame").get_attribute("src") is None  # the 3D view stops drawing
    assert page.get_by_role("button", name="2D view").get_attribute("aria-pressed") == "true"
    assert "in the 2D view" in page.locator("#status").inner_text()

    page.reload()  # the choice is kept in this browser
    page.locator("#top-view svg .object-fork").wait_for()
    assert page.locator("#viewer-frame").get_attribute("src") is None

    page.get_by_role("button", name="3D view").click()
    page.wait_for_function("() => document.getElementById('viewer-frame').getAttribute('src')")
    assert not page.locator("#top-view").is_visible()
    assert "in the 3D view" in page.locator("#status").inner_text()


BLOCK_MAIN_THREAD = "(ms) => { const end = performance.now() + ms; while (performance.now() < end) { /* stalled */ } }"


def test_a_page_that_stalls_under_the_3d_view_switches_to_the_2d_view_and_says_why(default_view_page, mujoco_server):
    page = default_view_page
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0)
    join_and_begin(page, mujoco_server.url, open_study(mujoco_server.url, spec), "stall-1")
    page.wait_for_function("() => document.getElementById('viewer-frame').getAttribute('src')")
    for _ in range(2):  # two stalls of more than 5 s, as software WebGL caused them on a loaded laptop
        page.evaluate(BLOCK_MAIN_THREAD, 5500)
        page.wait_for_timeout(600)  # the page's timers run in between
    page.locator("#top-view svg .object-bowl").wait_for()
    assert page.locator("#viewer-frame").get_attribute("src") is None
    assert "too slow" in page.locator("#view-mode-note").inner_text()
    assert page.get_by_role("button", name="3D view").is_enabled()  # the participant can switch back
