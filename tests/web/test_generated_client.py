"""A client generated from /openapi.json (openapi-python-client) types every field and runs a whole participant
session and an experimenter's study life (trace robot, in process)."""

from __future__ import annotations

import importlib
import io
import json
import shutil
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import pytest

from .conftest import EXPERIMENTER_TOKEN, QUESTIONNAIRE

GENERATOR = shutil.which("openapi-python-client") or str(Path(sys.executable).parent / "openapi-python-client")
# Binary answers through the generator's file type (it reads text/csv as text otherwise, then fails on bytes).
CONFIG = "content_type_overrides:\n  application/zip: application/octet-stream\n  text/csv: application/octet-stream\n"
PACKAGE = "tableteach_generated_client"

pytestmark = pytest.mark.skipif(not Path(GENERATOR).exists(), reason="openapi-python-client is not installed")


def _generate(schema: dict[str, Any], folder: Path) -> Any:
    """Generate the client package into folder and import it."""
    (folder / "openapi.json").write_text(json.dumps(schema))
    (folder / "config.yaml").write_text(CONFIG)
    env_path = f"{Path(sys.executable).parent}"
    done = subprocess.run([GENERATOR, "generate", "--path", str(folder / "openapi.json"), "--meta", "none",
                           "--output-path", str(folder / PACKAGE), "--config", str(folder / "config.yaml")],
                          capture_output=True, text=True, env={"PATH": env_path}, cwd=folder, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Warning" not in done.stdout, done.stdout  # nothing of the schema was left out of the client
    sys.path.insert(0, str(folder))
    try:
        return importlib.import_module(PACKAGE)
    finally:
        sys.path.remove(str(folder))


class _Tag:
    """The operations of one tag of the generated client, imported on first use."""

    def __init__(self, tag: str) -> None:
        self.tag = tag

    def __getattr__(self, name: str) -> Any:
        return importlib.import_module(f"{PACKAGE}.api.{self.tag}.{name}")


def _ok(response: Any, status: int = 200) -> Any:
    assert response.status_code == status, (response.status_code, response.content[:300])
    return response.parsed


def test_a_generated_client_runs_a_participant_session_and_a_study_life(app_client, tmp_path: Path) -> None:
    gen = _generate(app_client.get("/openapi.json").json(), tmp_path)
    models = importlib.import_module(f"{PACKAGE}.models")
    ex, me, analysis, exports = (_Tag(t) for t in ("experimenter", "participant", "analysis", "exports"))
    exp = gen.AuthenticatedClient(base_url="http://testserver", token=EXPERIMENTER_TOKEN)
    exp.set_httpx_client(app_client)  # the TestClient is an httpx client of the app
    app_client.headers["Authorization"] = f"Bearer {EXPERIMENTER_TOKEN}"
    spec = models.StudyIn.from_dict({"name": "generated", "tasks": [{"key": "task1"}], "conditions": ["active"],
                                     "n_practice": 0, "n_demonstrations": 1, "n_queries": 1, "n_tests": 1,
                                     "questionnaire": QUESTIONNAIRE, "completion_code": "GEN1"})
    study = _ok(ex.create_study.sync_detailed(client=exp, body=spec), 201)
    assert isinstance(study, models.StudyOut) and study.tasks[0].key.value == "task1"
    sid = study.id
    assert _ok(ex.describe_formula.sync_detailed(client=exp, formula="F(bowl)")).formula == "F(bowl)"
    patched = _ok(ex.update_study.sync_detailed(sid, client=exp, body=models.StudyPatch.from_dict(
        {"timed_out_code": "LATE2"})))
    assert patched.timed_out_code == "LATE2"
    assert _ok(ex.open_study.sync_detailed(sid, client=exp)).status.value == "open"

    joined = _ok(me.join.sync_detailed(sid, client=gen.Client(base_url="http://testserver").set_httpx_client(
        app_client)), 201)
    app_client.headers["Authorization"] = f"Bearer {joined.token}"
    person = gen.AuthenticatedClient(base_url="http://testserver", token=joined.token)
    person.set_httpx_client(app_client)
    state = joined.state
    assert state.stage.value == "consent" and isinstance(state.consent, models.ConsentOut)
    state = _ok(me.consent.sync_detailed(client=person, body=models.ConsentIn(agree=True,
                                                                                consent_version=state.consent.version)))
    state = _ok(me.instructions.sync_detailed(client=person))
    assert state.task.key.value == "task1" and state.step.kind.value == "demonstration"
    for obj in ("dinner_plate", "small_plate", "bowl", "knife", "fork"):
        state = _ok(me.place.sync_detailed(client=person, body=models.PlacementIn.from_dict({"object": obj})))
    assert state.demonstration.placed[-1] == "fork"
    state = _ok(me.finish.sync_detailed(client=person))  # the optional step guard left out
    for kind in ("query", "test"):
        assert state.step.kind.value == kind
        state = _ok(me.execute.sync_detailed(client=person))
        deadline = time.monotonic() + 60
        while state.execution.status.value != "finished" and time.monotonic() < deadline:
            time.sleep(0.02)
            state = _ok(me.get_state.sync_detailed(client=person))
        assert state.execution.status.value == "finished" and state.execution.trace
        state = _ok(me.assess.sync_detailed(client=person, body=models.AssessmentIn.from_dict(
            {"acceptable": True})))
    assert state.stage.value == "questionnaire" and state.questionnaire[0].kind.value == "likert5"
    state = _ok(me.questionnaire.sync_detailed(client=person, body=models.QuestionnaireIn.from_dict(
        {"answers": {"learned": 4, "overall": 8.0, "comments": "fine"}})))
    assert state.stage.value == "done" and state.completion.code == "GEN1" and state.progress.minutes_left == 0
    assert state.completion.learned[0].summary

    app_client.headers["Authorization"] = f"Bearer {EXPERIMENTER_TOKEN}"
    people = _ok(ex.list_participants.sync_detailed(sid, client=exp))
    assert people[0].outcome.value == "completed" and people[0].completion_code == "GEN1"
    pid = people[0].participant_id
    belief = _ok(ex.get_belief.sync_detailed(sid, pid, client=exp))
    assert belief.tasks[0].top[0].p > 0
    live = _ok(analysis.live.sync_detailed(sid, client=exp))
    assert live.participants[0].participant_id == pid
    history = _ok(analysis.history.sync_detailed(sid, pid, client=exp))
    assert history.events[0].kind == "joined"
    curves = _ok(analysis.curves.sync_detailed(sid, client=exp))
    assert curves.tasks
    csv_file = _ok(exports.export_csv.sync_detailed(sid, "participants", client=exp))
    assert b"GEN1" in csv_file.payload.read()
    archive = _ok(exports.export_zip.sync_detailed(sid, client=exp))
    assert "study.json" in zipfile.ZipFile(io.BytesIO(archive.payload.read())).namelist()
    copy = _ok(ex.clone_study.sync_detailed(sid, client=exp), 201)
    assert copy.status.value == "draft"
    assert _ok(ex.close_study.sync_detailed(sid, client=exp)).status.value == "closed"
    assert _ok(ex.reset_pilot.sync_detailed(sid, client=exp)).erased == []
    assert ex.erase_participant.sync_detailed(sid, pid, client=exp).status_code == 204
    assert _ok(ex.list_erasures.sync_detailed(sid, client=exp))[0].participant_id == pid
    assert _ok(_Tag("operations").health.sync_detailed(client=exp)).status == "ok"
