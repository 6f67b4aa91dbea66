"""Repeated submissions (double clicks, retries, two tabs) change nothing; conflicts are 409 with the state."""

from __future__ import annotations

import threading

import httpx
import pytest

from .conftest import ServerProcess, open_study, study_spec
from .helpers import bearer, demonstrate, make_study, to_teaching

ALL = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]


def _events(client, token: str) -> int:
    return client.get("/api/v1/me", headers=bearer(token)).json()["n_events"]


def test_same_key_twice_records_one_event_and_replays_the_state(app_client) -> None:
    token, _ = to_teaching(app_client, make_study(app_client))
    headers = {**bearer(token), "Idempotency-Key": "click-1"}
    first = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=headers)
    n = _events(app_client, token)
    second = app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=headers)
    assert first.status_code == second.status_code == 200
    assert second.json()["replayed"] is True and first.json()["replayed"] is False
    assert second.json()["demonstration"]["placed"] == ["bowl"]
    assert _events(app_client, token) == n


def test_same_key_for_a_different_request_is_a_conflict_with_the_state(app_client) -> None:
    token, _ = to_teaching(app_client, make_study(app_client))
    headers = {**bearer(token), "Idempotency-Key": "k-42"}
    assert app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=headers).status_code == 200
    clash = app_client.post("/api/v1/me/placements", json={"object": "fork"}, headers=headers)
    assert clash.status_code == 409
    assert "k-42" in clash.json()["detail"] and "already used" in clash.json()["detail"]
    assert clash.json()["state"]["demonstration"]["placed"] == ["bowl"]


def test_two_tabs_placing_the_same_object_and_a_stale_step(app_client) -> None:
    token, _ = to_teaching(app_client, make_study(app_client))
    h = bearer(token)
    assert app_client.post("/api/v1/me/placements", json={"object": "knife"}, headers=h).status_code == 200
    again = app_client.post("/api/v1/me/placements", json={"object": "knife"}, headers=h)
    assert again.status_code == 409 and "already on the table" in again.json()["detail"]
    assert again.json()["state"]["demonstration"]["placed"] == ["knife"]
    demonstrate(app_client, token, [])  # ends the practice trial
    stale = app_client.post("/api/v1/me/demonstration/finish", json={"step_kind": "practice", "step_index": 0},
                            headers=h)
    assert stale.status_code == 409
    assert "practice 1" in stale.json()["detail"] and "demonstration 1 of 2" in stale.json()["detail"]
    assert stale.json()["state"]["step"] == {"kind": "demonstration", "index": 0, "total": 2}


def test_double_click_on_run_and_assess_records_one_assessment(app_client) -> None:
    token, _ = to_teaching(app_client, make_study(app_client))
    h = bearer(token)
    for _ in range(3):
        demonstrate(app_client, token, ALL)
    first = app_client.post("/api/v1/me/execution", headers=h).json()
    second = app_client.post("/api/v1/me/execution", headers=h).json()
    assert first["execution"] == second["execution"] and first["n_events"] == second["n_events"]
    body = {"acceptable": False, "task_index": 0, "step_kind": "query", "step_index": 0}
    ok = app_client.post("/api/v1/me/assessment", json=body, headers=h)
    assert ok.status_code == 200 and ok.json()["step"]["index"] == 1
    dup = app_client.post("/api/v1/me/assessment", json=body, headers=h)
    assert dup.status_code == 409 and dup.json()["state"]["step"]["index"] == 1


@pytest.mark.slow
def test_concurrent_retries_with_one_key_against_a_real_server(shared_server: ServerProcess) -> None:
    study_id = open_study(shared_server.url, study_spec(["batch"]))
    with httpx.Client(base_url=shared_server.url) as http:
        joined = http.post(f"/api/v1/studies/{study_id}/join", json={}).json()
        h = bearer(joined["token"])
        http.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=h)
        http.post("/api/v1/me/instructions", headers=h)
        statuses: list[int] = []

        def submit() -> None:
            r = httpx.post(f"{shared_server.url}/api/v1/me/placements", json={"object": "fork"},
                           headers={**h, "Idempotency-Key": "same"})
            statuses.append(r.status_code)

        threads = [threading.Thread(target=submit) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        state = http.get("/api/v1/me", headers=h).json()
    assert statuses == [200] * 8
    assert state["demonstration"]["placed"] == ["fork"]
    assert state["n_events"] == 6  # joined, consent, instructions_read, task_started, one place, its labels
