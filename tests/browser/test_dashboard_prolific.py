"""The dashboard's Prolific screen in Debian's Chromium: upload Prolific's submissions export (a malformed one names
its cells and keeps nothing), the per-id table with mismatches flagged, the bonus rule and the bulk-bonus file; no
serious or critical axe-core violation at a laptop's and a phone's size."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from tableteach.client import ExperimenterClient, ParticipantClient, run_teacher
from tests.browser.accessibility import assert_accessible
from tests.browser.conftest import LiveServer
from tests.browser.test_dashboard import log_in
from tests.web.conftest import EXPERIMENTER_TOKEN, study_spec

EXPORT = ("Submission id,Participant id,Status,Started at,Completed at,Completion code\n"
          "s1,PDONE,APPROVED,2026-12-01 10:00,2026-12-01 10:20,DONE1\n"
          "s2,PDECLINED,APPROVED,2026-12-01 10:00,2026-12-01 10:01,NOPE2\n"
          "s3,PSTRANGER,RETURNED,2026-12-01 10:00,,\n")
MALFORMED = "Submission id,Participant id,Status\ns1,PDONE,APPROVED\ns2,P 2,FINISHED\n"


@pytest.fixture
def trace_server(tmp_path: Path) -> Any:
    """The app with the trace robot, served in a thread (quick to start on a busy machine)."""
    server = LiveServer(tmp_path, robot="trace").start()
    try:
        yield server
    finally:
        server.stop()


def _csv_file(name: str, text: str) -> dict[str, Any]:
    return {"name": name, "mimeType": "text/csv", "buffer": text.encode()}


@pytest.mark.browser
def test_the_experimenter_reconciles_with_prolific_and_downloads_the_bonus_file(
        trace_server: Any, browser_page: Any, tmp_path: Path) -> None:
    server = trace_server
    exp = ExperimenterClient(server.url, token=EXPERIMENTER_TOKEN)
    study = exp.create_study(study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0,
                                        completion_code="DONE1", declined_consent_code="NOPE2"))["id"]
    exp.open_study(study)
    done = run_teacher(server.url, study, ["task1"], seed=1, prolific_pid="PDONE")
    declined = ParticipantClient(server.url)
    state = declined.join(study, prolific_pid="PDECLINED", session_id="S-D")["state"]
    declined.consent(state["consent"]["version"], agree=False)
    declined.close()

    page = browser_page
    page.set_viewport_size({"width": 1366, "height": 768})
    log_in(page, server.url, EXPERIMENTER_TOKEN)
    page.wait_for_selector("#studies")
    page.goto(f"{server.url}/dashboard#/study/{study}")
    page.click("#open-prolific")
    page.wait_for_selector("#reconciliation")  # the participants with a Prolific id, before any upload
    assert "unknown on Prolific" in page.text_content("#reconciliation tr[data-pid='PDONE']")
    assert "no export uploaded yet" in page.text_content("#reconciliation-summary")

    # A malformed export: every bad cell named by row and column, nothing stored.
    page.set_input_files("#submissions-file", files=[_csv_file("bad.csv", MALFORMED)])
    page.click("#upload-form button[type=submit]")
    page.wait_for_selector("#upload-message .error li")
    problems = page.text_content("#upload-message")
    assert "bad.csv was not stored" in problems
    assert 'row 3, column Participant id: "P 2" is not a Prolific participant id' in problems
    assert 'row 3, column Status: "FINISHED" is not a Prolific status' in problems
    assert exp._json("GET", f"/api/v1/studies/{study}/prolific/reconciliation")["uploaded_at"] is None

    page.set_input_files("#submissions-file", files=[_csv_file("submissions.csv", EXPORT)])
    page.click("#upload-form button[type=submit]")
    page.wait_for_selector("#upload-message:has-text('3 submission(s) from submissions.csv')")
    page.wait_for_selector("#reconciliation tr[data-pid='PSTRANGER']")
    rows = {pid: page.text_content(f"#reconciliation tr[data-pid='{pid}']")
            for pid in ("PDONE", "PDECLINED", "PSTRANGER")}
    assert "agrees" in rows["PDONE"] and "completed" in rows["PDONE"] and f"#{done.participant_id}" in rows["PDONE"]
    assert "approved on Prolific but declined consent here" in rows["PDECLINED"] and "NOPE2" in rows["PDECLINED"]
    assert "unknown here" in rows["PSTRANGER"] and "never joined" in rows["PSTRANGER"]
    assert "2 mismatch(es)" in page.text_content("#reconciliation-summary")
    page.check("#mismatches-only")
    assert page.locator("#reconciliation tr[data-pid='PDONE']").is_hidden()
    assert page.locator("#reconciliation tr[data-pid='PDECLINED']").is_visible()
    assert_accessible(page, "Prolific (laptop)")

    # The bonus rule: a refused amount is named next to its field; then the file follows the rule.
    assert "No bonus rule yet" in page.text_content("#bonus-preview")
    page.fill("#bonus-completed", "150")
    assert page.evaluate("document.getElementById('bonus-completed').validity.rangeOverflow")  # the browser says no
    page.evaluate("document.getElementById('bonus-completed').removeAttribute('max')")  # and so does the server:
    page.click("#bonus-form button[type=submit]")
    page.wait_for_selector("[data-error-for='amounts.completed']:not(:empty)")
    assert "100" in page.text_content("[data-error-for='amounts.completed']")
    page.fill("#bonus-completed", "1.5")
    page.fill("#bonus-declined_consent", "0.25")
    page.click("#bonus-form button[type=submit]")
    page.wait_for_selector("#bonus-lines")
    assert "2 bonus(es)" in page.text_content("#bonus-summary") and "1.75 in all" in page.text_content("#bonus-summary")
    assert page.input_value("#bonus-completed") == "1.50"
    assert exp._json("GET", f"/api/v1/studies/{study}/prolific/bonus-rule")["amounts"] == {
        "completed": "1.50", "declined_consent": "0.25"}
    with page.expect_download() as downloaded:
        page.click("#download-bonuses")
    saved = tmp_path / "bonuses.csv"
    downloaded.value.save_as(saved)
    assert downloaded.value.suggested_filename == f"{study}-bonuses.csv"
    assert sorted(saved.read_text().splitlines()) == ["PDECLINED,0.25", "PDONE,1.50"]
    assert_accessible(page, "Prolific with a bonus file (laptop)")
    shots = os.environ.get("TABLETEACH_SCREENSHOTS")
    if shots:
        page.screenshot(path=f"{shots}/prolific-1366.png", full_page=True)

    page.set_viewport_size({"width": 390, "height": 844})
    page.reload()
    page.wait_for_selector("#bonus-lines")
    assert_accessible(page, "Prolific (phone)")
    if shots:
        page.screenshot(path=f"{shots}/prolific-390.png", full_page=True)
    assert page.evaluate("document.documentElement.scrollWidth") <= 390 + 1  # wide tables scroll in their card
