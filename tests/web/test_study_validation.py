"""One study validator for the API and the services, and its messages in plain words."""

from __future__ import annotations

import re
from typing import Any

import pytest

from tableteach import services
from tableteach.errors import InvalidFields
from tableteach.services.study_definition import StudyIn

from .helpers import EXP

BAD_SPECS: list[dict[str, Any]] = [
    {"tasks": [{"key": "custom"}], "n_tests": None, "pilot": 1, "robot_speed": "fast"},
    {"tasks": [], "conditions": ["active", "active"], "prior": None, "colour": "red"},
    {"tasks": [{"key": "task3"}], "completion_code": "has space", "completion_url": "ftp://x",
     "timeout_minutes": 0, "quiz_max_attempts": True},
    {"tasks": [{"key": "none", "ground_truth": "F(bowl)"}], "n_queries": 21.5,
     "questionnaire": [{"id": "a", "text": "?", "kind": "attention"}, {"id": "a", "text": "?", "kind": "likert5"}],
     "quiz": [{"id": "q", "text": "?", "options": ["a", ""], "correct": 1}]},
    {"tasks": "task1", "name": "x" * 300, "questionnaire": [{"id": "b c", "kind": "sometimes"}]},
    {"tasks": [{"key": "task1"}], "allow_anonymous": None, "quiz_feedback": "yes", "consent_form": {"researcher": 5},
     "questionnaire": [{"id": "a", "text": "?", "kind": "likert5", "anchors": [1, None]}]},
]
PYTHON_WORDS = re.compile(r"\bNone\b|\bTrue\b|\bFalse\b|Input should|dict\b|\bstr\b|\bint\b|\[|\]")


@pytest.mark.parametrize("spec", BAD_SPECS)
def test_the_api_and_the_services_give_the_same_plain_errors(app_client, spec: dict[str, Any]) -> None:
    r = app_client.post("/api/v1/studies", json=spec, headers=EXP)
    assert r.status_code == 422, r.text
    api_errors = r.json()["errors"]
    with pytest.raises(InvalidFields) as raised:
        services.create_study(app_client.ctx, spec)
    assert raised.value.errors == api_errors
    for error in api_errors:
        assert not PYTHON_WORDS.search(error["message"]), error
        assert error["field"] in r.json()["detail"]


def test_every_unacceptable_field_is_named_once_with_what_was_expected(app_client) -> None:
    r = app_client.post("/api/v1/studies", json=BAD_SPECS[3], headers=EXP)
    errors = {e["field"]: e["message"] for e in r.json()["errors"]}
    assert set(errors) == {"tasks.0.ground_truth", "n_queries", "questionnaire.0.expected", "questionnaire.1.id",
                           "quiz.0.options.1"}, errors
    assert "custom" in errors["tasks.0.ground_truth"] and "whole number" in errors["n_queries"]
    assert "already" in errors["questionnaire.1.id"]
    r = app_client.post("/api/v1/studies", json=BAD_SPECS[2], headers=EXP)
    errors = {e["field"]: e["message"] for e in r.json()["errors"]}
    assert errors["completion_code"] == 'must be letters, digits, - or _ (as in Prolific\'s completion codes), ' \
                                        'got "has space"'
    assert errors["tasks.0.key"] == 'is "task3"; expected one of task1, task2, custom or none'
    assert errors["timeout_minutes"] == "must be a number from 1 to 1440, got 0"
    assert errors["quiz_max_attempts"] == "must be a whole number from 1 to 10, got true"


def test_the_schema_of_a_study_definition_is_the_validators_model(app_client) -> None:
    schema = app_client.get("/openapi.json").json()
    study_in = schema["components"]["schemas"]["StudyIn"]
    assert set(study_in["properties"]) == set(StudyIn.model_fields)
    assert study_in["additionalProperties"] is False
    good = {"tasks": [{"key": "custom", "ground_truth": "F(bowl)"}], "conditions": ["batch"]}
    assert services.study_problems(good) == []
    assert app_client.post("/api/v1/studies", json=good, headers=EXP).status_code == 201
