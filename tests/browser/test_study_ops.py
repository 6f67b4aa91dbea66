"""Study operations in Debian's Chromium: the comprehension quiz, the Withdraw link with its confirmation, the
redirect after declining consent, and the experimenter's edit, clone and erase in the dashboard.

Run `python tests/browser/test_study_ops.py OUT_DIR` to save screenshots of these screens at 1366x768."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import httpx
import pytest

if __name__ == "__main__":  # run as a script: make `tests` importable, as pytest does
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tests.browser.conftest import LiveServer  # noqa: E402
from tests.web.conftest import EXPERIMENTER_TOKEN, QUESTIONNAIRE  # noqa: E402

EXP = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}
VIEWPORT = {"width": 1366, "height": 768}
# Elements with the hidden attribute that still take room on screen (style.css hides every one of them).
HIDDEN_SHOWN = """() => [...document.querySelectorAll('[hidden]')].filter(e => e.getClientRects().length > 0)
    .map(e => e.id || e.className || e.tagName)"""
QUIZ = [{"id": "who", "text": "Who places the objects during a demonstration?",
         "options": ["I choose them and the robot places them", "The robot chooses by itself"], "correct": 0},
        {"id": "order", "text": "Can the order of the objects matter?", "options": ["Yes", "No"], "correct": 0}]


def make_study(url: str, **extra: Any) -> str:
    """An open one-task study with a quiz and study-level codes; its id."""
    spec = {"name": "Quiz study", "tasks": [{"key": "task1"}], "conditions": ["batch"], "n_practice": 0,
            "n_demonstrations": 1, "n_queries": 0, "n_tests": 0, "questionnaire": QUESTIONNAIRE, "quiz": QUIZ,
            "completion_url": f"{url}/healthz?cc={{code}}", "completion_code": "DONE42",
            "screened_out_code": "SCREEN7", **extra}
    study = httpx.post(f"{url}/api/v1/studies", json=spec, headers=EXP)
    assert study.status_code == 201, study.text
    httpx.post(f"{url}/api/v1/studies/{study.json()['id']}/open", headers=EXP).raise_for_status()
    return study.json()["id"]


@pytest.fixture
def live_server(tmp_path: Path) -> Any:
    """The app with the trace robot, served in a thread."""
    server = LiveServer(tmp_path, robot="trace").start()
    try:
        yield server
    finally:
        server.stop()


def consent(page: Any) -> None:
    page.click("button:has-text('I agree')")
    page.click("button:has-text('Start')")


@pytest.mark.browser
def test_quiz_then_withdraw_with_confirmation(live_server: Any, browser_page: Any, tmp_path: Path) -> None:
    study = make_study(live_server.url)
    page = browser_page
    page.set_viewport_size(VIEWPORT)
    page.goto(f"{live_server.url}/study/{study}/join?PROLIFIC_PID=B1")
    page.wait_for_selector("button:has-text('I agree')")
    assert page.locator("#withdraw-link").is_hidden()  # nothing to withdraw from before consent
    assert page.evaluate(HIDDEN_SHOWN) == []
    consent(page)
    page.wait_for_selector("form.quiz")
    assert page.locator("#withdraw-link").is_visible()
    assert page.evaluate(HIDDEN_SHOWN) == [] and page.locator("#task").is_hidden()
    assert page.locator("#study-progress-text").inner_text().startswith("Step 1 of ")
    page.check("input[name=quiz-who][value='1']")
    page.check("input[name=quiz-order][value='0']")
    page.click("form.quiz button[type=submit]")
    page.wait_for_selector("#quiz-retry")
    assert "last try" in page.text_content("#quiz-retry")
    assert page.evaluate(HIDDEN_SHOWN) == []
    page.check("input[name=quiz-who][value='0']")
    page.check("input[name=quiz-order][value='0']")
    page.click("form.quiz button[type=submit]")
    page.wait_for_selector("button:has-text('Begin this task')")
    # A tab that no longer holds the page (another took it over) offers no withdrawal; taking it back does.
    other = page.context.new_page()
    try:
        other.goto(page.url)
        other.wait_for_selector("#elsewhere")
        assert other.locator("#withdraw-link").is_hidden()
        other.click("#elsewhere button")
        other.wait_for_selector("button:has-text('Begin this task')")
        page.wait_for_selector("#elsewhere")
        assert page.locator("#withdraw-link").is_hidden() and page.evaluate(HIDDEN_SHOWN) == []
    finally:
        other.close()
    page.click("#elsewhere button")
    page.wait_for_selector("button:has-text('Begin this task')")
    assert page.locator("#withdraw-link").is_visible()
    # Withdraw: the confirmation can be cancelled; confirming deletes the data and says so.
    page.click("#withdraw-link")
    page.click("#withdraw-cancel")
    assert page.locator("#withdraw-dialog").is_hidden()
    token = page.url.rsplit("/", 1)[1]
    assert httpx.get(f"{live_server.url}/api/v1/me", headers={"Authorization": f"Bearer {token}"}).json()[
        "stage"] == "task"
    page.click("#withdraw-link")
    page.click("#withdraw-confirm")
    page.wait_for_selector("#ended")
    assert "withdrawn" in page.text_content("#ended h1") and "deleted" in page.text_content("#ended")
    assert page.locator("#withdraw-link").is_hidden() and page.locator("#study-progress").is_hidden()
    assert page.evaluate(HIDDEN_SHOWN) == []
    events = httpx.get(f"{live_server.url}/api/v1/studies/{study}/exports/events.csv", headers=EXP).text
    assert [line.split(",")[3] for line in events.splitlines()[1:]] == ["withdrawn"]


@pytest.mark.browser
def test_declining_consent_redirects_with_the_screened_out_code(live_server: Any, browser_page: Any) -> None:
    study = make_study(live_server.url)
    page = browser_page
    page.goto(f"{live_server.url}/study/{study}/join?PROLIFIC_PID=B2")
    page.click("button:has-text('I do not agree')")
    page.wait_for_selector("#ended #redirect")
    assert page.get_attribute("#redirect", "href") == f"{live_server.url}/healthz?cc=SCREEN7"
    first = page.locator("#countdown").inner_text()
    # The countdown counts, as on the done page: a later second replaces the first one still on this page.
    page.wait_for_function("first => { const c = document.getElementById('countdown'); "
                           "return c !== null && c.textContent !== first; }", arg=first)
    page.wait_for_url(f"{live_server.url}/healthz?cc=SCREEN7")  # taken back without a click


def screenshots(out_dir: Path) -> None:
    """Screens of this module at 1366x768: the quiz, the withdraw confirmation, the dashboard's form and table."""
    import tempfile
    import time

    from tableteach.client import run_teacher
    from tests.browser.conftest import launch_chromium
    from tests.browser.test_dashboard import log_in

    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        server = LiveServer(Path(tmp), robot="trace").start()
        try:
            study = make_study(server.url, quiz=[], name="Dinner table, counterbalanced",
                               tasks=[{"key": "task1"}, {"key": "task2"}], task_order="balanced",
                               conditions=["active", "random"], timeout_minutes=30)
            for seed in range(3):
                run_teacher(server.url, study, ["task1", "task2"], seed=seed, prolific_pid=f"P{seed}")
            run_teacher(server.url, study, ["task1", "task2"], seed=9, stop_after=4, prolific_pid="P9")
            quiz_study = make_study(server.url)
            with launch_chromium(VIEWPORT) as context:
                page = context.new_page()
                page.goto(f"{server.url}/study/{quiz_study}/join?PROLIFIC_PID=S1")
                consent(page)
                page.wait_for_selector("form.quiz")
                page.screenshot(path=str(out_dir / "quiz.png"))
                page.click("#withdraw-link")
                time.sleep(0.3)
                page.screenshot(path=str(out_dir / "withdraw.png"))
                log_in(page, server.url, EXPERIMENTER_TOKEN)
                page.wait_for_selector("#studies")
                page.goto(f"{server.url}/dashboard#/study/{study}")
                page.wait_for_selector("#participants")
                time.sleep(0.5)
                page.screenshot(path=str(out_dir / "study.png"), full_page=True)
                page.goto(f"{server.url}/dashboard#/new")
                page.wait_for_selector("#new-study-form")
                page.select_option("#tasks select", "custom")
                page.fill("#tasks input[name=ground_truth]", "F(bowl) & (!fork U knife)")
                page.fill("#n_tests", "30")
                page.click("#create")
                page.wait_for_selector("#create-message .error")
                time.sleep(0.5)
                page.screenshot(path=str(out_dir / "form.png"), full_page=True)
                page.evaluate("window.scrollTo(0, 0)")
                page.screenshot(path=str(out_dir / "form-top.png"))
                page.goto(f"{server.url}/")
                page.screenshot(path=str(out_dir / "home.png"))
        finally:
            server.stop()


if __name__ == "__main__":
    screenshots(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("screenshots"))
