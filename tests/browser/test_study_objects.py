"""A study with its own objects in headless Chromium with the MuJoCo robot: the page names its objects, shows its
goal picture, and a participant demonstrates with its objects and answers one of the robot's queries."""

from __future__ import annotations

import pytest

from tests.study_objects import LUNCH_TRUTH, lunch_study
from tests.web.conftest import open_study

from conftest import TIMEOUT_MS

pytestmark = pytest.mark.browser


def test_a_participant_demonstrates_and_answers_a_query_in_a_study_with_its_own_objects(browser_page, mujoco_server):
    page = browser_page
    spec = lunch_study(tasks=[{"key": "custom", "ground_truth": LUNCH_TRUTH, "name": "Pack the lunch box"}],
                       n_tests=0)
    study_id = open_study(mujoco_server.url, spec)
    page.goto(f"{mujoco_server.url}/study/{study_id}/join?PROLIFIC_PID=objects-1")
    page.get_by_role("button", name="I agree, continue").click()
    instructions = page.locator(".instructions-body").inner_text()
    assert "five objects (a lunch box, an apple, a napkin, a spoon and a mug)" in instructions
    assert "dinner" not in instructions
    assert page.locator(".topbar .brand").inner_text() == "Teach a robot a task"
    page.get_by_role("button", name="Start").click()
    goal = page.locator("figure.goal img")
    assert goal.get_attribute("src") == f"/study/{study_id}/goal/0.svg"
    page.wait_for_function("() => document.querySelector('figure.goal img').naturalWidth > 0")
    page.get_by_role("button", name="Begin this task").click()

    page.get_by_role("heading", name="Show the robot how to do the task").wait_for()
    buttons = page.eval_on_selector_all("button.object", "nodes => nodes.map((n) => n.dataset.object)")
    assert buttons == ["lunch_box", "apple", "napkin", "spoon", "mug"]
    assert page.locator("#viewer-frame").get_attribute("src")  # the 3D view of the study's own scene
    for obj, name in (("lunch_box", "lunch box"), ("spoon", "spoon"), ("napkin", "napkin")):
        page.wait_for_selector("#finish:not([disabled])", timeout=TIMEOUT_MS)
        page.locator(f'button.object[data-object="{obj}"]').click()
        page.wait_for_function("(n) => document.querySelector('.placed')?.textContent.includes(n)", arg=name,
                               timeout=TIMEOUT_MS)
    page.wait_for_selector("#finish:not([disabled])", timeout=TIMEOUT_MS)
    page.get_by_role("button", name="Finish demonstration").click()

    page.get_by_role("button", name="Watch the robot").click()
    page.wait_for_selector("#acceptable:not([disabled])", timeout=TIMEOUT_MS)
    assert page.locator(".question").inner_text() == "Is this an acceptable way to do this task?"
    outcome = page.locator("#outcome").inner_text()
    assert "It placed, in this order:" in outcome and "dinner" not in outcome
    page.get_by_role("button", name="Unacceptable").click()
    page.wait_for_selector("form.questionnaire", timeout=TIMEOUT_MS)
