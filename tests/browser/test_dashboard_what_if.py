"""The dashboard's teacher-consistency flag and "what if" panel in Debian's Chromium: a perfect scripted teacher
and one who flips every verdict complete a study; the live table flags what the API flags, and the participant's
page replays their data through other learners, matching the API's numbers."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from tableteach.client import run_teacher
from tests.browser.accessibility import serious_violations
from tests.web.conftest import (  # noqa: F401  (server_factory is a fixture used by name)
    EXPERIMENTER_TOKEN,
    open_study,
    server_factory,
    study_spec,
)

EXP = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}


@pytest.mark.browser
def test_the_flag_and_what_if_in_the_dashboard(server_factory: Any, browser_page: Any) -> None:  # noqa: F811
    server = server_factory()
    study_id = open_study(server.url, study_spec(["active"], n_queries=2, n_tests=2, name="What-if study"))
    runs = [run_teacher(server.url, study_id, ["task1"], noise=0.0, seed=4)]
    # A teacher who flips every verdict is flagged only if a verdict of theirs had a low probability, which depends
    # on the session's random seed (a misled learner may plan tests the truth rejects): up to five such teachers.
    for seed in range(5, 10):
        runs.append(run_teacher(server.url, study_id, ["task1"], noise=1.0, seed=seed))
        live = httpx.get(f"{server.url}/api/v1/studies/{study_id}/live", headers=EXP).json()
        flagged = {row["participant_id"]: row["consistency"]["flagged"] for row in live["participants"]}
        if flagged[runs[-1].participant_id]:
            break
    assert all(r.completion_code for r in runs)
    flipping = runs[-1].participant_id
    assert flagged[flipping], "none of five teachers who flip every verdict was flagged"

    page = browser_page
    page.set_viewport_size({"width": 1280, "height": 800})
    page.goto(f"{server.url}/dashboard")
    page.fill("#token", EXPERIMENTER_TOKEN)
    page.click("#token-login button[type=submit]")
    page.click("#studies a:has-text('What-if study')")
    for run in runs:  # the live table's pill is the API's flag
        row = page.locator(f"#participants tr[data-participant='{run.participant_id}']")
        row.wait_for()
        assert row.locator("[data-consistency=flagged]").count() == int(flagged[run.participant_id])

    history = httpx.get(f"{server.url}/api/v1/studies/{study_id}/participants/{flipping}/history", headers=EXP).json()
    consistency = history["tasks"][0]["consistency"]
    page.goto(f"{server.url}/dashboard#/study/{study_id}/p/{flipping}")
    note = page.locator("section.task .consistency")
    note.wait_for()
    assert f"{consistency['score']:.2f}" in note.text_content() and "improbable verdict" in note.text_content()

    # What if: the default choices (noise-aware 0.1, demonstrations only) beside the study's own learner.
    page.click("#what-if-run")
    page.wait_for_selector("#what-if .what-if-task table")
    shown = {tr.get_attribute("data-learner"): tr.locator("td").nth(4).text_content()
             for tr in page.locator("#what-if .what-if-finals tbody tr").all()}
    api = httpx.get(f"{server.url}/api/v1/studies/{study_id}/participants/{flipping}/what-if",
                    params=[("learner", "flip=0.1"), ("learner", "data=demonstrations")], headers=EXP).json()
    expected = {x["learner"]: f"{x['steps'][-1]['similarity']:.3f}" for x in api["tasks"][0]["learners"]}
    assert shown == expected and set(shown) == {"study", "flip=0.1", "data=demonstrations"}
    assert expected["study"] == f"{history['tasks'][0]['steps'][-1]['similarity']:.3f}"
    assert page.locator("#what-if svg").count() == 1
    assert serious_violations(page) == []

    # A learner the server does not know: its message, in place of the results.
    page.fill("#what-if-custom", "flips=0.1")
    page.click("#what-if-run")
    page.wait_for_selector("#what-if .error")
    assert "unknown learner 'flips=0.1'" in page.text_content("#what-if .error")
