"""Study statistics (funnel, completion times, condition x task-order cells), archiving and deleting."""

from __future__ import annotations

from .conftest import study_spec
from .helpers import EXP, bearer, join, make_study
from .test_study_ops import SHORT, finish


def test_statistics_count_the_funnel_the_completion_times_and_the_cells(app_client) -> None:
    study = make_study(app_client, tasks=[{"key": "task1"}, {"key": "task2"}], task_order="balanced", **SHORT)
    done = [finish(app_client, study) for _ in range(2)]
    token, _ = join(app_client, study)
    app_client.post("/api/v1/me/consent", json={"agree": False, "consent_version": "1"}, headers=bearer(token))
    join(app_client, study)
    data = app_client.get(f"/api/v1/studies/{study}/statistics", headers=EXP).json()
    assert [(f["stage"], f["n"]) for f in data["funnel"]] == [
        ("joined", 4), ("consented", 2), ("started", 2), ("finished_tasks", 2), ("completed", 2)]
    assert data["outcomes"]["completed"] == 2 and data["outcomes"]["declined_consent"] == 1
    times = data["completion_seconds"]
    assert times["n"] == 2 and times["values"] == sorted(times["values"]) and times["median"] is not None
    assert sum(c["n"] for c in data["cells"]) == 4
    assert {tuple(c["task_order"]) for c in data["cells"]} <= {(0, 1), (1, 0)}
    assert all(c["tasks"][0].startswith("Task") for c in data["cells"])
    assert len(done) == 2


def test_archiving_hides_a_study_and_deleting_refuses_one_with_participants(app_client) -> None:
    study = make_study(app_client, **SHORT)
    join(app_client, study)
    r = app_client.delete(f"/api/v1/studies/{study}", headers=EXP)
    assert r.status_code == 409 and "archive it instead" in r.json()["detail"]
    archived = app_client.post(f"/api/v1/studies/{study}/archive", headers=EXP).json()
    assert archived["status"] == "closed" and archived["archived_at"]
    assert study not in [s["id"] for s in app_client.get("/api/v1/studies", headers=EXP).json()]
    assert study in [s["id"] for s in app_client.get("/api/v1/studies?include_archived=true", headers=EXP).json()]
    back = app_client.post(f"/api/v1/studies/{study}/unarchive", headers=EXP).json()
    assert back["archived_at"] is None and back["status"] == "closed"
    draft = app_client.post("/api/v1/studies", json=study_spec(["active"]), headers=EXP).json()["id"]
    assert app_client.delete(f"/api/v1/studies/{draft}", headers=EXP).status_code == 204
    assert app_client.get(f"/api/v1/studies/{draft}", headers=EXP).status_code == 404
    assert app_client.delete(f"/api/v1/studies/{draft}", headers=EXP).status_code == 404
