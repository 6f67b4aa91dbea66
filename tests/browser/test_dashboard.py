"""The experimenter dashboard in Debian's Chromium: log in, live table, per-participant view, curves, CSV downloads.

Run `python tests/browser/test_dashboard.py [out.png]` to render docs/dashboard.png from a study with a few
scripted participants.
"""

from __future__ import annotations

import csv
import io
import sys
from pathlib import Path
from typing import Any

import httpx
import pytest

if __name__ == "__main__":  # run as a script: make `tests` importable, as pytest does
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from tableteach.client import ExperimenterClient, ParticipantClient, run_teacher  # noqa: E402
from tests.web.conftest import (  # noqa: E402, F401  (server_factory is a fixture used by name)
    EXPERIMENTER_TOKEN,
    ServerProcess,
    open_study,
    server_factory,
    study_spec,
)

VIEWPORT = {"width": 1280, "height": 800}
OUT = Path(__file__).resolve().parents[2] / "docs" / "dashboard.png"


def rows(text: str) -> list[dict[str, str]]:
    """CSV text as dicts."""
    return list(csv.DictReader(io.StringIO(text, newline="")))


def log_in(page: Any, url: str, token: str) -> None:
    """Open the dashboard and submit a token."""
    page.goto(f"{url}/dashboard")
    page.fill("#token", token)
    page.click("#token-login button[type=submit]")


@pytest.mark.browser
def test_experimenter_follows_a_session_in_the_dashboard(server_factory: Any, browser_page: Any) -> None:  # noqa: F811
    server = server_factory()
    study_id = open_study(server.url, study_spec(["active"], n_queries=2, n_tests=1, name="Browser study"))
    run = run_teacher(server.url, study_id, ["task1"], seed=4, prolific_pid="PB1")
    pid = run.participant_id
    assert run.completion_code
    page = browser_page
    page.set_viewport_size(VIEWPORT)

    # A participant's token opens nothing: the login says why and the API answers 401.
    log_in(page, server.url, run.token)
    page.wait_for_selector("#login-message .error")
    message = page.text_content("#login-message .error")
    assert "refused this token" in message and "participant links and tokens do not give access" in message
    assert page.evaluate("sessionStorage.length") == 0
    for path in ("/api/v1/studies", f"/api/v1/studies/{study_id}/live",
                 f"/api/v1/studies/{study_id}/participants/{pid}/history"):
        assert httpx.get(server.url + path, headers={"Authorization": f"Bearer {run.token}"}).status_code == 401

    # The experimenter logs in and sees the participant in the live table.
    page.fill("#token", EXPERIMENTER_TOKEN)
    page.click("#token-login button[type=submit]")
    page.click("#studies a:has-text('Browser study')")
    row = page.locator(f"#participants tr[data-participant='{pid}']")
    row.wait_for()
    assert "done" in row.text_content() and run.completion_code in row.text_content() and "PB1" in row.text_content()
    assert page.input_value("#join-link") == f"{server.url}/study/{study_id}/join"

    # Polling: a participant who joins now appears without a reload.
    newcomer = ParticipantClient(server.url)
    try:
        state = newcomer.join(study_id, prolific_pid="PB2")["state"]
        newcomer.consent(state["consent"]["version"])
        newcomer.instructions()
    finally:
        newcomer.close()
    fresh = page.locator(f"#participants tr[data-participant='{state['participant_id']}']")
    fresh.wait_for()  # the page polls every few seconds: the default limit (120 s) covers many polls
    assert "practice 1/1" in fresh.text_content() and "active" in fresh.text_content()

    # Study curves: one similarity and one entropy chart, with the participant count in the legend.
    curves = page.locator(".task-curves[data-task='0'] svg.chart")
    curves.first.wait_for()
    assert curves.count() == 2
    assert "active (n=2)" in page.text_content(".task-curves[data-task='0']")

    # CSV downloads hold exactly the session.
    exp = ExperimenterClient(server.url, token=EXPERIMENTER_TOKEN)
    downloaded = {}
    try:
        for name in ("participants", "events", "beliefs", "questionnaire"):
            with page.expect_download() as info:
                page.click(f"#downloads button[data-export='{name}']")
            downloaded[name] = Path(info.value.path()).read_text(encoding="utf-8")
            assert info.value.suggested_filename == f"{study_id}-{name}.csv"
            assert rows(downloaded[name]) == rows(exp.export(study_id, name))
    finally:
        exp.close()
    people = {r["participant_id"]: r for r in rows(downloaded["participants"])}
    assert people[str(pid)]["completion_code"] == run.completion_code and people[str(pid)]["stage"] == "done"
    mine = [r for r in rows(downloaded["events"]) if r["participant_id"] == str(pid)]
    assert [r["kind"] for r in mine if r["kind"] == "assessment"] == ["assessment"] * 3
    verdicts = [a["acceptable"] for a in run.actions if a["kind"] == "query"]
    [test_verdict] = [a["acceptable"] for a in run.actions if a["kind"] == "test"]
    label = {True: "acceptable", False: "unacceptable"}
    beliefs = [r for r in rows(downloaded["beliefs"]) if r["participant_id"] == str(pid)]
    assert [r["record_kind"] for r in beliefs] == ["", "demonstration", "demonstration", "query", "query"]
    assert [r["acceptable"] for r in beliefs[3:]] == [str(v).lower() for v in verdicts]
    answers = next(a["answers"] for a in run.actions if a["kind"] == "questionnaire")
    got = {r["item_id"]: r["answer"] for r in rows(downloaded["questionnaire"]) if r["participant_id"] == str(pid)}
    assert got == {k: ("'" + v if isinstance(v, str) and v.startswith("=") else str(v)) for k, v in answers.items()}

    # Per-participant view: every step with its label, the belief after each step and the curves.
    row.locator("a").click()
    task = page.locator("section.task[data-task='0']")
    task.wait_for()
    kinds = task.locator("table.executions tbody tr").evaluate_all(
        "rows => rows.map(r => [r.dataset.kind, Number(r.dataset.index), r.querySelector('.pill').textContent])")
    assert kinds == [["practice", 0, "practice"], ["demonstration", 0, "acceptable"],
                     ["demonstration", 1, "acceptable"], ["query", 0, label[verdicts[0]]],
                     ["query", 1, label[verdicts[1]]], ["test", 0, label[test_verdict]]]
    assert task.locator("svg.chart").count() == 2  # entropy and similarity per learning step
    history = httpx.get(f"{server.url}/api/v1/studies/{study_id}/participants/{pid}/history",
                        headers={"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}).json()
    steps = history["tasks"][0]["steps"]
    for k in range(len(steps)):
        task.locator(f".segmented button[data-step='{k}']").click()
        belief = task.locator(f".belief[data-step='{k}']")
        belief.wait_for()
        assert belief.locator(".description").first.text_content() == steps[k]["top"][0]["description"]
        assert f"{steps[k]['entropy']:.2f}" in belief.text_content()

    # Replay of the first query (trace robot: no recording, so the trace is replayed step by step).
    task.locator("button[data-replay='query-0']").click()
    replay = task.locator(".replay[data-source='trace']")
    replay.wait_for()
    replay.locator("input[type=range]").evaluate("el => { el.value = 1000; el.dispatchEvent(new Event('input')); }")
    final = history["tasks"][0]["executions"][3]["trace"][-1]
    placed = replay.locator("g.object.placed").evaluate_all("gs => gs.map(g => g.dataset.object).sort()")
    assert placed == sorted(final)


def make_screenshot(out: Path = OUT) -> None:
    """A study with a few scripted participants; the per-participant view at 1280x800 with a replay open."""
    import tempfile
    import time

    from tests.browser.conftest import launch_chromium

    with tempfile.TemporaryDirectory() as tmp:
        server = ServerProcess(Path(tmp) / "study.db").start()
        try:
            spec = study_spec(["active", "random"], name="Dinner table: Active vs Random queries")
            study_id = open_study(server.url, spec)
            for seed in range(6):
                run_teacher(server.url, study_id, ["task1"], noise=0.1 * (seed % 2), seed=seed,
                            prolific_pid=f"P{seed:03d}")
            run_teacher(server.url, study_id, ["task1"], seed=11, stop_after=5, prolific_pid="P011")
            # Show a participant in the active condition replaying a query in which the robot placed most objects.
            exp = ExperimenterClient(server.url, token=EXPERIMENTER_TOKEN)
            try:
                active = [p["participant_id"] for p in exp.participants(study_id) if p["condition"] == "active"]
            finally:
                exp.close()
            pid = active[0]
            history = httpx.get(f"{server.url}/api/v1/studies/{study_id}/participants/{pid}/history",
                                headers={"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}).json()
            queries = [x for x in history["tasks"][0]["executions"] if x["kind"] == "query"]
            query = max(queries, key=lambda x: len(x["trace"]))["index"]
            with launch_chromium(VIEWPORT) as context:
                page = context.new_page()
                log_in(page, server.url, EXPERIMENTER_TOKEN)
                page.wait_for_selector("#studies")
                page.goto(f"{server.url}/dashboard#/study/{study_id}/p/{pid}")
                page.wait_for_selector("section.task")
                page.click(f"button[data-replay='query-{query}']")
                page.wait_for_selector(".replay")
                page.locator(".replay input[type=range]").evaluate(
                    "el => { el.value = 700; el.dispatchEvent(new Event('input')); }")
                page.locator("section.task").evaluate("el => window.scrollTo(0, el.offsetTop - 64)")
                time.sleep(0.5)
                page.screenshot(path=str(out))
        finally:
            server.stop()


if __name__ == "__main__":
    make_screenshot(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)


@pytest.mark.browser
def test_experimenter_creates_and_opens_a_study(server_factory: Any, browser_page: Any) -> None:  # noqa: F811
    server = server_factory()
    page = browser_page
    page.set_viewport_size(VIEWPORT)
    log_in(page, server.url, EXPERIMENTER_TOKEN)
    page.click("#new-study")
    page.fill("#name", "Made in the browser")
    page.select_option("#tasks select", "custom")
    page.fill("#tasks input[name=ground_truth]", "F(spoon)")
    page.check("#condition_random")
    page.click("#add-item")
    page.fill("[name=item_id]", "easy")
    page.fill("[name=item_text]", "Teaching was easy.")
    page.fill("#n_tests", "25")
    page.fill("#robot_speed", "5")
    page.click("#create")
    error = page.locator("#create-message .error")
    error.wait_for()
    assert "3 fields need a change" in error.text_content()
    # Each refused field says why next to itself, both at once, in plain words.
    assert "spoon" in page.text_content("[data-error-for='tasks.0.ground_truth']")
    assert "0 to 20" in page.text_content("[data-error-for='n_tests']")
    assert "1 to 3" in page.text_content("[data-error-for='robot_speed']")
    page.fill("#n_tests", "2")
    page.fill("#robot_speed", "1.5")
    page.fill("#tasks input[name=ground_truth]", "F(bowl) & (!bowl U dinner_plate)")
    words = page.locator(".formula-words.ok")
    words.wait_for()
    assert "bowl" in words.text_content() and "dinner plate" in words.text_content().replace("_", " ")
    page.fill("#tasks input[name=task_name]", "Plate before bowl")
    page.click("#create")
    page.wait_for_selector("#open-study")
    study_id = page.evaluate("decodeURIComponent(location.hash.split('/')[2])")
    def study() -> dict[str, Any]:
        return httpx.get(f"{server.url}/api/v1/studies/{study_id}",
                         headers={"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}).json()

    created = study()
    assert (created["name"], created["status"], created["conditions"]) == (
        "Made in the browser", "draft", ["active", "random"])
    assert created["tasks"][0]["key"] == "custom" and "(!bowl U dinner_plate)" in created["tasks"][0]["ground_truth"]
    assert created["tasks"][0]["name"] == "Plate before bowl" and created["n_tests"] == 2
    assert created["robot_speed"] == 1.5
    assert created["questionnaire"] == [
        {"id": "easy", "text": "Teaching was easy.", "kind": "likert5", "required": True, "expected": None,
         "anchors": None, "instrument": None, "instrument_item": None}]
    asked: list[str] = []
    page.once("dialog", lambda dialog: (asked.append(dialog.message), dialog.accept()))
    page.click("#open-study")
    page.wait_for_selector("#close-study")
    assert "Anyone with the link can join" in asked[0]  # opening is confirmed first
    assert study()["status"] == "open"
    assert page.input_value("#join-link") == f"{server.url}/study/{study_id}/join"
