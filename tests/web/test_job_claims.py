"""Claiming jobs (db/jobs.py): a placement's job is held for the process whose request stored it, which claims it at
once, while another process takes it only after HELD_SECONDS (the first one died); a job under way is never
claimed twice; quick kinds come first and a runner of quick kinds takes nothing else."""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

import pytest

from tableteach.db import jobs as job_rows
from tableteach.db.tables import utcnow
from tableteach.services.runtime import FINISH_EXECUTION, HELD_SECONDS, QUICK_KINDS, SETTLE, WORK_OUT

from .helpers import join, make_study


@pytest.fixture
def quiet(app_client: Any) -> tuple[Any, int, datetime]:
    """The app with its runtime stopped (these tests claim by hand), a participant's id and the time now."""
    from tableteach.services.state import participant_and_study

    app_client.ctx.runtime.stop()
    token, _ = join(app_client, make_study(app_client))
    with app_client.ctx.db.read() as s:
        return app_client, participant_and_study(s, token)[0].id, utcnow()


def _claim(s: Any, owner: str, at: datetime, **options: Any) -> list[job_rows.ClaimedJob]:
    """What `owner` claims at `at` (a 30 s lease, up to 4 jobs)."""
    return job_rows.claim_jobs(s, owner=owner, lease_seconds=30, limit=4, now=at, **options)


def _seconds_after(start: datetime, at: datetime | None) -> float:
    """Seconds from start to at (the database may hand naive UTC times back)."""
    assert at is not None, "no job can be claimed"
    return (at.replace(tzinfo=None) - start.replace(tzinfo=None)).total_seconds()


def test_a_held_job_is_its_process_s_at_once_and_anyones_after_the_hold(quiet: tuple[Any, int, datetime]) -> None:
    client, pid, now = quiet
    with client.ctx.db.write() as s:
        job_rows.add_job(s, kind=SETTLE, participant_id=pid, task_index=0, payload={}, due_at=now,
                         held_for="A", held_seconds=HELD_SECONDS)
        s.commit()
    with client.ctx.db.read() as s:  # A may claim it now; B once the hold is over
        assert _seconds_after(now, job_rows.next_claimable(s, owner="A")) == 0.0
        assert abs(_seconds_after(now, job_rows.next_claimable(s, owner="B")) - HELD_SECONDS) < 1e-3
    with client.ctx.db.write() as s:
        assert _claim(s, "B", now) == []
        (claimed,) = _claim(s, "A", now)
        assert claimed.kind == SETTLE and claimed.attempts == 1
        # under way at A: neither A's other runners nor B take it until its lease runs out
        assert _claim(s, "A", now) == [] and _claim(s, "B", now + timedelta(seconds=5)) == []
        (again,) = _claim(s, "B", now + timedelta(seconds=31))
        assert again.id == claimed.id and again.attempts == 2
        s.rollback()


def test_a_held_job_whose_process_is_gone_is_taken_after_the_hold(quiet: tuple[Any, int, datetime]) -> None:
    client, pid, now = quiet
    with client.ctx.db.write() as s:
        job_rows.add_job(s, kind=SETTLE, participant_id=pid, task_index=0, payload={}, due_at=now,
                         held_for="gone", held_seconds=HELD_SECONDS)
        assert _claim(s, "B", now + timedelta(seconds=HELD_SECONDS / 2)) == []
        (taken,) = _claim(s, "B", now + timedelta(seconds=HELD_SECONDS + 0.1))
        assert taken.kind == SETTLE
        s.rollback()


def test_quick_kinds_come_first_and_a_quick_runner_takes_nothing_else(quiet: tuple[Any, int, datetime]) -> None:
    client, pid, now = quiet
    for options, expected in (({"kinds": QUICK_KINDS}, [FINISH_EXECUTION]),
                              ({"first": QUICK_KINDS}, [FINISH_EXECUTION, WORK_OUT])):  # the older work-out after
        with client.ctx.db.write() as s:
            job_rows.add_job(s, kind=WORK_OUT, participant_id=pid, task_index=0, payload={},
                             due_at=now - timedelta(1))
            job_rows.add_job(s, kind=FINISH_EXECUTION, participant_id=pid, task_index=0, payload={}, due_at=now)
            assert [j.kind for j in _claim(s, "A", now, **options)] == expected
            s.rollback()


def test_a_placement_stores_its_settle_job_held_for_the_process_that_took_it(tmp_path: Any) -> None:
    from .conftest import in_process_app
    from .helpers import bearer, to_teaching
    from .test_executions import SlowRobot  # places in the background, as the MuJoCo robot does

    with in_process_app(tmp_path, SlowRobot()) as client:
        client.ctx.runtime.stop()  # the job stays stored, unclaimed
        token, _ = to_teaching(client, make_study(client, n_practice=0))
        assert client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token)).status_code == 200
        with client.ctx.db.read() as s:
            (job,) = job_rows.pending_jobs(s)
            assert (job.kind, job.claimed_by, job.attempts) == (SETTLE, client.ctx.runtime.owner, 0)
            assert _seconds_after(job.due_at, job.claimed_until) == HELD_SECONDS
