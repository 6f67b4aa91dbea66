"""Concurrent retries with one Idempotency-Key on PostgreSQL replay the answer, as they do on SQLite."""

from __future__ import annotations

import threading
from pathlib import Path

import httpx
import pytest

from .conftest import ServerProcess, open_study, study_spec
from .test_postgres import postgres_url  # noqa: F401  (the module's throwaway cluster)

pytestmark = pytest.mark.slow


def test_concurrent_retries_with_one_key_all_get_the_replayed_answer(postgres_url: str,  # noqa: F811
                                                                     tmp_path: Path) -> None:
    server = ServerProcess(tmp_path / "unused.db", database_url=postgres_url).start()
    try:
        study_id = open_study(server.url, study_spec(["active"]))
        with httpx.Client(base_url=server.url, timeout=30) as client:
            joined = client.post(f"/api/v1/studies/{study_id}/join", json={}).json()
            h = {"Authorization": f"Bearer {joined['token']}"}
            version = joined["state"]["consent"]["version"]
            assert client.post("/api/v1/me/consent", json={"agree": True, "consent_version": version},
                               headers=h).status_code == 200
            assert client.post("/api/v1/me/instructions", headers=h).status_code == 200
            n_before = client.get("/api/v1/me", headers=h).json()["n_events"]
        for round_, obj in enumerate(["bowl", "fork", "knife"]):
            barrier = threading.Barrier(8)
            answers: list[httpx.Response] = []

            def retry(obj: str = obj, round_: int = round_, barrier: threading.Barrier = barrier,
                      answers: list[httpx.Response] = answers) -> None:
                with httpx.Client(base_url=server.url, timeout=30) as c:
                    barrier.wait()
                    answers.append(c.post("/api/v1/me/placements", json={"object": obj},
                                          headers={**h, "Idempotency-Key": f"place-{round_}"}))

            threads = [threading.Thread(target=retry) for _ in range(8)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            assert [a.status_code for a in answers] == [200] * 8, [a.text for a in answers if a.status_code != 200]
            assert sum(not a.json()["replayed"] for a in answers) == 1
            assert all(a.json()["demonstration"]["placed"][-1] == obj for a in answers)
        with httpx.Client(base_url=server.url, timeout=30) as client:
            me = client.get("/api/v1/me", headers=h).json()
        assert me["n_events"] == n_before + 6 and me["demonstration"]["placed"] == ["bowl", "fork", "knife"]
    finally:
        server.stop()
