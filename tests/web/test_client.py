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
