"""The Python client: bounded retries of 503 and 429 honouring Retry-After, and the scripted teacher that answers
the quiz and the attention checks from the study definition and refuses studies it cannot finish."""

from __future__ import annotations

import json
from typing import Any

import httpx
import pytest

from tableteach.client import ApiError, ExperimenterClient, StudyKnowledge, _Base, run_teacher

from .conftest import EXPERIMENTER_TOKEN, QUESTIONNAIRE, open_study, study_spec


def _flaky(statuses: list[int], retry_after: str | None = "2") -> tuple[_Base, list[float], list[str]]:
    """A client whose server answers the given statuses in turn (then 200)."""
    answers = list(statuses)
    seen: list[str] = []

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request.headers.get("Idempotency-Key", ""))
        status = answers.pop(0) if answers else 200
        headers = {"Retry-After": retry_after} if retry_after is not None and status in (429, 503) else {}
        return httpx.Response(status, json={"detail": "busy"} if status >= 400 else {"ok": True}, headers=headers)

    waits: list[float] = []
    client = _Base("http://fake", sleep=waits.append)
    client.http = httpx.Client(base_url="http://fake", transport=httpx.MockTransport(handler))
    return client, waits, seen


def test_a_503_or_429_is_retried_after_retry_after_with_the_same_key() -> None:
    client, waits, keys = _flaky([503, 429])
    assert client._json("POST", "/api/v1/me/instructions") == {"ok": True}
    assert waits == [2.0, 2.0] and len(set(keys)) == 1 and keys[0]


def test_retries_are_bounded_and_a_non_repeatable_post_is_not_retried_on_503() -> None:
    client, waits, _ = _flaky([503] * 10, retry_after="999")
    with pytest.raises(ApiError) as raised:
        client._json("GET", "/api/v1/me")
    assert raised.value.status == 503 and waits == [30.0, 30.0, 30.0]  # capped, 4 attempts in all
    client, waits, _ = _flaky([503])
    with pytest.raises(ApiError):
        client._json("POST", "/api/v1/studies", {}, idempotent=False)  # could have been stored: not repeated
    assert waits == []


QUIZ = [{"id": "who", "text": "Who places the objects?", "options": ["I do", "The robot"], "correct": 1}]
ITEMS = [*QUESTIONNAIRE, {"id": "attn", "text": "Choose Disagree.", "kind": "attention", "expected": 2}]


def _spec(**extra: Any) -> dict[str, Any]:
    return study_spec(["batch"], n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0, quiz=QUIZ,
                      questionnaire=ITEMS, **extra)


def test_the_teacher_answers_the_quiz_and_attention_checks_from_the_definition(shared_server) -> None:
    study = open_study(shared_server.url, _spec())
    with ExperimenterClient(shared_server.url, token=EXPERIMENTER_TOKEN) as exp:
        knows = StudyKnowledge.of_study(exp.study_spec(study))
        run = run_teacher(shared_server.url, study, ["task1"], seed=1, knows=knows)
        assert run.completion_code and [a["kind"] for a in run.actions][:3] == ["consent", "instructions", "quiz"]
        failing = StudyKnowledge.of_study(exp.study_spec(study), attention_fail_rate=1.0)
        bad = run_teacher(shared_server.url, study, ["task1"], seed=2, knows=failing)
        people = {p["participant_id"]: p for p in exp.participants(study)}
    assert people[run.participant_id]["attention_failed"] is False
    assert people[bad.participant_id]["attention_failed"] is True


def test_the_teacher_refuses_before_joining_a_study_it_cannot_finish(shared_server) -> None:
    study = open_study(shared_server.url, _spec())
    with ExperimenterClient(shared_server.url, token=EXPERIMENTER_TOKEN) as exp:
        spec = exp.study_spec(study)
        before = len(exp.participants(study))
        no_answers = StudyKnowledge(n_tasks=1, has_quiz=True)
        with pytest.raises(ValueError, match="quiz"):
            run_teacher(shared_server.url, study, ["task1"], knows=no_answers)
        with pytest.raises(ValueError, match="2 ground truths"):
            run_teacher(shared_server.url, study, ["task1", "task2"], knows=StudyKnowledge.of_study(spec))
        assert len(exp.participants(study)) == before  # nobody joined


def test_tableteach_teach_with_the_token_finishes_a_quiz_study(shared_server) -> None:
    import subprocess
    import sys

    study = open_study(shared_server.url, _spec())
    done = subprocess.run([sys.executable, "-m", "tableteach.cli", "teach", "--server", shared_server.url, "--study",
                           study, "--ground-truth", "task1", "--token", EXPERIMENTER_TOKEN],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["completion_code"]
    refused = subprocess.run([sys.executable, "-m", "tableteach.cli", "teach", "--server", shared_server.url,
                              "--study", study, "--ground-truth", "task1", "--quiz-answers", "who"],
                             capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2 and "ITEM=NUMBER" in refused.stderr and "Traceback" not in refused.stderr


def _template(path: str) -> Any:
    """A regex matching the concrete paths of an OpenAPI path template."""
    import re

    return re.compile("^" + "[^/]+".join(re.escape(part) for part in re.split(r"\{[^}]+\}", path)) + "$")


def test_the_client_has_a_method_for_every_endpoint_of_the_schema(app_client) -> None:
    """Every operation in /openapi.json is called once through ParticipantClient or ExperimenterClient, against the
    real app, and answers a success."""
    import time

    from tableteach.client import ParticipantClient

    calls: list[tuple[str, str, int]] = []

    def client(cls: Any, **kwargs: Any) -> Any:
        made = cls("http://testserver", on_request=lambda name, _s, status: calls.append((*name.split(" ", 1), status)),
                   **kwargs)
        made.http = app_client
        return made

    exp = client(ExperimenterClient, token=EXPERIMENTER_TOKEN)
    exp.health()
    exp.instruments()
    exp.describe_formula("F(bowl)")
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0, quiz=QUIZ,
                      completion_code="DONE1", pilot=True)
    study = exp.create_study(spec)["id"]
    exp.get_study(study)
    exp.study_spec(study)
    exp.update_study(study, {"name": "renamed"})
    copy = exp.clone_study(study)["id"]
    exp.delete_study(copy)
    exp.list_studies(include_archived=True)
    exp.open_study(study)

    p = client(ParticipantClient)
    state = p.join(study, prolific_pid="P1", session_id="S1")["state"]
    p.consent(state["consent"]["version"])
    p.instructions()
    p.quiz({"who": 1})
    p.state()
    p.claim_tab("tab-0001")
    p.view()
    for obj in ("dinner_plate", "bowl"):
        state = p.place(obj)
    while not state["demonstration"].get("settled", True):
        time.sleep(0.02)
        state = p.state()
    p.finish()
    state = p.execute()
    while state["execution"]["status"] != "finished":
        time.sleep(0.02)
        state = p.state()
    with pytest.raises(ApiError, match="no 3D view"):  # the trace robot records no motion: refused, not missing
        p.replay_execution()
    p.robot()
    p.top_view()
    p.signal("tab_hidden")
    p.assess(True)
    p.release_tab("tab-0001")
    p.questionnaire({"learned": 4, "overall": 7})
    pid = state["participant_id"]
    leaver = client(ParticipantClient)
    leaver.consent(leaver.join(study, prolific_pid="P2", session_id="S2")["state"]["consent"]["version"])
    leaver.withdraw()
    stuck = client(ParticipantClient)
    stuck_id = stuck.join(study, prolific_pid="P3", session_id="S3")["state"]["participant_id"]
    stuck.consent("1", agree=False)

    exp.participants(study)
    exp.live(study)
    exp.history(study, pid)
    exp.belief(study, pid)
    replay_rows = exp.what_if(study, pid, ["flip=0.2"])["tasks"][0]["learners"]
    assert [row["learner"] for row in replay_rows] == ["study", "flip=0.2"]
    exp.curves(study)
    exp.replay(study, pid, 0, "query", 0)
    exp.statistics(study, include_pilot=True)
    exp.export(study, "participants")
    exp.export_zip(study)
    exp.restore_participant(study, stuck_id)
    stuck.consent("1")
    exp.help_participant(study, stuck_id)
    exp.erase_participant(study, stuck_id)
    exp.erasures(study)
    exp.reset_pilot(study)
    exp.upload_submissions(study, "Participant id,Status\nP1,APPROVED\n")
    exp.reconciliation(study)
    exp.set_bonus_rule(study, {"completed": 1})
    exp.bonus_rule(study)
    exp.bonus_file(study)
    exp.add_person("ada", "experimenter", "correct horse battery")
    exp.people()
    exp.revoke_token(exp.issue_token("ada", days=1)["id"])
    exp.tokens()
    exp.set_password("ada", "another long secret")
    ada = client(ExperimenterClient)
    ada.login("ada", "another long secret")
    ada.whoami()
    ada.change_password("another long secret", "a third long secret")
    exp.disable_person("ada")
    exp.audit()
    exp.audit_csv()
    exp.close_study(study)
    exp.archive_study(study)
    exp.unarchive_study(study)

    assert [c for c in calls if c[2] >= 400] == [("POST", "/api/v1/me/execution/replay", 409)]
    operations = {(method.upper(), path) for path, ops in app_client.app.openapi()["paths"].items()
                  for method in ops if method in ("get", "post", "put", "patch", "delete")}
    called = {(m, path) for m, path in operations for method, concrete, _ in calls
              if method == m and _template(path).match(concrete.split("?")[0])}
    assert operations - called == set()


def test_the_session_timeout_is_three_times_the_servers_estimate_and_at_least_ten_minutes() -> None:
    from tableteach.client import session_timeout

    assert session_timeout({"progress": {"minutes_left": 18}}, None) == 3240.0  # the demo study's estimate
    assert session_timeout({"progress": {"minutes_left": 2}}, None) == 600.0
    assert session_timeout({}, None) == 1800.0  # no estimate: ten minutes assumed
    assert session_timeout({"progress": {"minutes_left": 18}}, 90.0) == 90.0
