"""Schema fuzzing (schemathesis): no request generated from the OpenAPI schema gets a 500, with or without auth."""

from __future__ import annotations

import re
import warnings

import pytest
import schemathesis
from hypothesis import HealthCheck, settings

from tableteach.config import Settings
from tableteach.db.migrate import upgrade_head
from tableteach.web.app import create_app

from .conftest import EXPERIMENTER_TOKEN

pytestmark = pytest.mark.slow


def _app():  # type: ignore[no-untyped-def]
    import tempfile

    folder = tempfile.mkdtemp(prefix="tableteach-fuzz-")
    url = f"sqlite:///{folder}/fuzz.db"
    upgrade_head(url)
    app = create_app(Settings(database_url=url, experimenter_token=EXPERIMENTER_TOKEN, robot="trace",
                              joins_per_address=100_000))
    # Schemathesis sends many invalid keys on purpose: the wrong-key limit (tested in test_abuse_limits.py) would
    # answer 429 where the schema promises 401.
    from tableteach.web.limits import AddressLimiter

    app.state.key_failures = AddressLimiter(limit=1_000_000)
    return app


APP = _app()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    schema = schemathesis.openapi.from_asgi("/openapi.json", APP)


def _participant_token() -> str:
    from tableteach import services

    ctx = APP.state.context
    services.seed_demo_study(ctx)
    state, _ = services.join_study(ctx, "demo")
    services.give_consent(ctx, state["token"], agree=True, consent_version="1")
    services.finish_instructions(ctx, state["token"])
    return state["token"]


TOKEN = _participant_token()
# Every check runs, allow_header_conformance among them (a 405 or an OPTIONS answer names every method of the
# path), and positive_data_acceptance: a request valid by the schema is never refused with 400 or 422, with two
# exceptions JSON Schema cannot say: two questionnaire (or quiz) items with the same id, and what the rows of an
# uploaded Prolific export (a CSV text) must hold.
EXCLUDED = [schemathesis.checks.positive_data_acceptance]
NOT_IN_ANY_SCHEMA = "is already the id of an earlier item"
# ... and, for standard-questionnaire items, the cross-field rules: an instrument_item belongs to the instrument
# named, and an anchored kind has its two labels; for a study's own objects, what depends on the other objects
# (distinct names, slots clear of each other and within the arm's reach, room on Table A, the formulas' objects); a
# placement of an object the participant's study does not have; a formula over objects the study (or the dinner
# table) does not have.
CROSS_FIELD = re.compile(r"^(questionnaire\.\d+\.(instrument|instrument_item|anchors)|objects(\.\d+\.(name|slot))?"
                         r"|tasks\.\d+\.(ground_truth|key))$")
OTHER_OBJECTS = ("is not an object of this study", "unknown proposition", "names an object twice")


def _refused_only_for_what_no_schema_says(case, response) -> bool:  # type: ignore[no-untyped-def]
    if response.status_code != 422:
        return False
    if case.path.endswith("/prolific/submissions"):
        return True
    if any(words in (response.json().get("detail") or "") for words in OTHER_OBJECTS):
        return True
    errors = response.json().get("errors") or []
    return bool(errors) and all(NOT_IN_ANY_SCHEMA in e["message"] or CROSS_FIELD.match(e["field"]) for e in errors)


@schema.parametrize()
@settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
def test_no_server_errors(case) -> None:  # type: ignore[no-untyped-def]
    path = case.path
    if path.startswith("/api/v1/me"):
        headers = {"Authorization": f"Bearer {TOKEN}"}
    elif path.startswith("/api/v1/studies") and not path.endswith("/join"):
        headers = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}
    else:
        headers = {}
    response = case.call(headers={**(case.headers or {}), **headers})
    assert response.status_code < 500, f"{case.method} {path}: {response.status_code} {response.text[:300]}"
    case.validate_response(response, excluded_checks=EXCLUDED)
    if not _refused_only_for_what_no_schema_says(case, response):
        case.validate_response(response, checks=EXCLUDED)
