"""Small helpers for in-process API tests (TestClient)."""

from __future__ import annotations

import itertools
import secrets
from typing import Any

from tableteach.client import ParticipantClient, run_teacher
from tableteach.services import TASK_FORMULAS

from .conftest import EXPERIMENTER_TOKEN, study_spec

EXP = {"Authorization": f"Bearer {EXPERIMENTER_TOKEN}"}


def bearer(token: str) -> dict[str, str]:
    """Authorization header of a participant."""
    return {"Authorization": f"Bearer {token}"}


def make_study(client: Any, conditions: list[str] | None = None, **extra: Any) -> str:
    """Create and open a study in-process; its id."""
    return open_spec(client, study_spec(conditions or ["active"], **extra))


def open_spec(client: Any, spec: dict[str, Any]) -> str:
    """Create a study from a whole spec in-process and open it; its id."""
    response = client.post("/api/v1/studies", json=spec, headers=EXP)
    assert response.status_code == 201, response.text
    study_id = response.json()["id"]
    assert client.post(f"/api/v1/studies/{study_id}/open", headers=EXP).status_code == 200
    return study_id


def join(client: Any, study_id: str, **body: Any) -> tuple[str, dict[str, Any]]:
    """Join; the token and state."""
    response = client.post(f"/api/v1/studies/{study_id}/join", json=body)
    assert response.status_code in (200, 201), response.text
    return response.json()["token"], response.json()["state"]


def to_teaching(client: Any, study_id: str) -> tuple[str, dict[str, Any]]:
    """Join, consent and read the instructions: the first task's practice trial is next."""
    token, state = join(client, study_id)
    h = bearer(token)
    assert client.post("/api/v1/me/consent", json={"agree": True, "consent_version": state["consent"]["version"]},
                       headers=h).status_code == 200
    response = client.post("/api/v1/me/instructions", headers=h)
    assert response.status_code == 200, response.text
    return token, response.json()


def demonstrate(client: Any, token: str, objects: list[str]) -> dict[str, Any]:
    """Place objects and finish the demonstration."""
    for obj in objects:
        assert client.post("/api/v1/me/placements", json={"object": obj}, headers=bearer(token)).status_code == 200
    response = client.post("/api/v1/me/demonstration/finish", headers=bearer(token))
    assert response.status_code == 200, response.text
    return response.json()


def participant_uid(ctx: Any, participant_id: int) -> str:
    """The random uid of a participant (it names their robot recordings)."""
    from tableteach.db.tables import ParticipantRow

    with ctx.db.read() as s:
        return s.get(ParticipantRow, participant_id).uid


# (seed, teacher's flip probability): two perfect teachers, one who flips every verdict
TEACHERS = ((0, 0.0), (1, 0.0), (2, 1.0))


class FixedSessionSeeds:
    """The secrets module for the participants service, but each new participant's session seed is the next of
    a fixed sequence: the robot's queries and plans then do not vary from run to run."""

    def __init__(self) -> None:
        self._seeds = itertools.count(1000)

    def randbelow(self, n: int) -> int:
        return next(self._seeds) % n

    def __getattr__(self, name: str) -> Any:
        return getattr(secrets, name)


def teach(client: Any, study_id: str) -> list[int]:
    """The scripted teachers complete the study; their participant ids."""
    ids = []
    for seed, noise in TEACHERS:
        api = ParticipantClient("http://testserver")
        api.http = client  # the in-process app speaks the same HTTP
        run = run_teacher("http://testserver", study_id, [TASK_FORMULAS["task1"]], noise=noise, seed=seed,
                          client=api, poll_seconds=0.0, timeout=120)
        assert run.completion_code
        ids.append(run.participant_id)
    return ids
