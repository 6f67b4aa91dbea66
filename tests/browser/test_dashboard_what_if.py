"""The dashboard's teacher-consistency flag and "what if" panel in Debian's Chromium: two perfect scripted
teachers and one who flips every verdict complete a study; the live table flags what the API flags, and the
participant's page replays their data through other learners, matching the API's numbers."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterator

import httpx
import pytest

from tableteach.services import participants as participants_service
from tests.browser.accessibility import serious_violations
from tests.web.conftest import EXPERIMENTER_TOKEN, ServerProcess, in_process_app
from tests.web.helpers import FixedSessionSeeds, make_study, teach

EXP = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}


@pytest.fixture
def taught(tmp_path: Path) -> Iterator[tuple[ServerProcess, str, list[int]]]:
    """A server on a study two perfect teachers and one who flips every verdict completed: taught in-process with
    fixed session seeds (whether the flipping teacher is flagged depends on the seed), then served as a lab would."""
    with pytest.MonkeyPatch.context() as patch, in_process_app(tmp_path) as client:
        patch.setattr(participants_service, "secrets", FixedSessionSeeds())
        study_id = make_study(client, ["active"], name="What-if study")
        ids = teach(client, study_id)
    server = ServerProcess(tmp_path / "app.db").start()
    try:
        yield server, study_id, ids
    finally:
        server.stop()


@pytest.mark.browser
def test_the_flag_and_what_if_in_the_dashboard(taught: tuple[Any, str, list[int]], browser_page: Any) -> None:
    server, study_id, ids = taught
    live = httpx.get(f"{server.url}/api/v1/studies/{study_id}/live", headers=EXP).json()
    flagged = {row["participant_id"]: row["consistency"]["flagged"] for row in live["participants"]}
    flipping = ids[-1]
    assert flagged == {ids[0]: False, ids[1]: False, flipping: True}

    page = browser_page
    page.set_viewport_size({"width": 1280, "height": 800})
    page.goto(f"{server.url}/dashboard")
    page.fill("#token", EXPERIMENTER_TOKEN)
    page.click("#token-login button[type=submit]")
    page.click("#studies a:has-text('What-if study')")
    for pid in ids:  # the live table's pill is the API's flag
        row = page.locator(f"#participants tr[data-participant='{pid}']")
        row.wait_for()
        assert row.locator("[data-consistency=flagged]").count() == int(flagged[pid])

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
