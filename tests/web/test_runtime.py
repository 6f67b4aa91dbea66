"""The runtime's guarantees: reads never write (GET endpoints, the dashboard's read models, the exports), an
action's effects run after its transaction has ended, and what a read shows of a finished execution or a
time-out is recorded by the runtime, not by whoever looked."""

from __future__ import annotations

import threading
from datetime import timedelta
from pathlib import Path
from typing import Any

from sqlalchemy import event

from tableteach.db.tables import ParticipantRow
from tableteach.robot import TraceRobot

from .conftest import in_process_app
from .helpers import EXP, bearer, demonstrate, make_study, to_teaching


class CommitCounter:
    """Counts the database commits made while it is installed on an engine."""

    def __init__(self, engine: Any) -> None:
        self.count = 0
        self._lock = threading.Lock()
        event.listen(engine, "commit", self._commit)

    def _commit(self, _conn: Any) -> None:
        with self._lock:
            self.count += 1


def _reads(client: Any, study: str, token: str) -> None:
    """Everything a page, a dashboard or an analyst reads."""
    for path in ("/api/v1/me", "/api/v1/me/robot"):
        assert client.get(path, headers=bearer(token)).status_code == 200, path
    assert client.get(f"/p/{token}").status_code == 200
    for path in (f"/api/v1/studies/{study}/live", f"/api/v1/studies/{study}",
                 *(f"/api/v1/studies/{study}/exports/{name}.csv"
                   for name in ("participants", "events", "steps", "beliefs", "questionnaire", "codebook")),
                 f"/api/v1/studies/{study}/exports/exports.zip"):
        assert client.get(path, headers=EXP).status_code == 200, path


def test_reads_never_commit_even_when_an_execution_has_run_out_or_a_participant_is_idle(tmp_path: Path) -> None:
    with in_process_app(tmp_path, TraceRobot("dinner", seconds_per_object=0.0)) as client:
        study = make_study(client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0, timeout_minutes=5)
        token, _ = to_teaching(client, study)
        idle, _ = to_teaching(client, study)
        demonstrate(client, token, ["dinner_plate", "fork"])
        client.ctx.runtime.stop()  # nothing records the finish now: only a read could, and it must not
        started = client.post("/api/v1/me/execution", headers=bearer(token)).json()
        with client.ctx.db.write() as s:  # a participant idle past the time-out, not yet swept
            p = s.query(ParticipantRow).filter(ParticipantRow.token == idle).one()
            p.last_activity_at = p.last_activity_at - timedelta(minutes=6)
            s.commit()
        commits = CommitCounter(client.ctx.db.engine)
        _reads(client, study, token)
        _reads(client, study, idle)
        assert commits.count == 0
        shown = client.get("/api/v1/me", headers=bearer(token)).json()["execution"]
        assert started["execution"]["status"] in ("running", "finished")
        assert shown["status"] == "finished" and shown["trace"][-1] == sorted(shown["events"])  # by its clock
        assert client.get("/api/v1/me", headers=bearer(idle)).json()["stage"] == "task"  # not yet swept
        # The verdict (a write) records the finish the read only showed.
        r = client.post("/api/v1/me/assessment", json={"acceptable": True}, headers=bearer(token))
        assert r.status_code == 200, r.text


def test_an_effect_runs_after_the_transaction_so_its_own_write_never_waits_for_the_lock(app_client: Any) -> None:
    from tableteach.services.state import act

    ctx = app_client.ctx
    token, _ = to_teaching(app_client, make_study(app_client, n_practice=0))
    seen: dict[str, Any] = {}

    def effect() -> None:
        seen["lock_held"] = ctx.db._write_lock.locked()
        with ctx.db.write() as s:  # would wait the busy timeout and fail (503) under the action's own lock
            s.query(ParticipantRow).filter(ParticipantRow.token == token).one().last_activity_at  # noqa: B018
            s.commit()
        seen["wrote"] = True

    def run(a: Any) -> None:
        a.log("test_effect", {})
        a.after(effect)

    ctx.db.busy_seconds = 0.5
    state = act(ctx, token, "test-effect", {}, None, run)
    assert seen == {"lock_held": False, "wrote": True}
    assert state["stage"] == "task"


def test_the_runtime_sweep_screens_out_the_idle_and_their_open_page_is_told(tmp_path: Path) -> None:
    from tableteach.config import Settings

    with in_process_app(tmp_path) as client:
        ctx = client.ctx
        study = make_study(client, n_practice=0, timeout_minutes=5)
        token, state = to_teaching(client, study)
        pid = int(state["participant_id"])
        with ctx.db.write() as s:
            p = s.query(ParticipantRow).filter(ParticipantRow.token == token).one()
            p.last_activity_at = p.last_activity_at - timedelta(minutes=6)
            s.commit()
        before = ctx.notifier.counter(pid)
        assert isinstance(ctx.settings, Settings)
        ctx.runtime.sweep_seconds = 0.05
        ctx.runtime.call_later(0.0, ctx.runtime._sweep)
        import time

        deadline = time.monotonic() + 60
        while client.get("/api/v1/me", headers=bearer(token)).json()["stage"] != "screened_out":
            assert time.monotonic() < deadline, "the runtime never swept the idle participant out"
            time.sleep(0.05)
        assert ctx.notifier.counter(pid) > before
