"""Durable background work (services.runtime runs it): what each kind of job does.

Every job is written in the transaction of the action that needs it, so nothing a participant waits for
lives only in a thread's memory. Each handler reads what is stored, does the robot's part outside any
transaction, then stores the result in a short transaction of its own, checking first that the session is
still where the job found it. Running a handler twice (a retry, a lease that ran out, two processes) changes
nothing the first run stored: labels and plans are stored only where they are missing.

- settle: the robot places a demonstration's stored objects (rebuilding its table from the stored
  placements if it lost it) and the labels it reports are stored (event `placed`).
- work_out: the robot works a query or test execution out (physics, recording) and its plan is stored;
  its clock starts then. With recordings kept in the database, the execution's files are stored with the plan.
- finish_execution: at the stored end of an execution, it is recorded as finished (event
  `execution_finished`).
- plan_ahead: the robot's next turn is planned (and, for a robot that records, worked out) before the
  participant asks for it; past five objects on the runtime's learner thread, not the job runner's.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, TypeGuard

from ..core import learner_seam as seam
from ..core import session as core
from ..db import jobs as job_rows
from ..db import recording_rows
from ..db import repository as repo
from ..db.tables import ParticipantRow, StudyRow, TaskSessionRow, utcnow
from ..recording_store import VISER_SUFFIX, RecordingId
from . import executions, placements
from .context import Context
from .planning import ROBOT_TURNS, position_of, session_of
from .runtime import FINISH_EXECUTION, PLAN_AHEAD, SETTLE, WORK_OUT, Handler
from .state import Action, current_task, sync_execution, table_key

log = logging.getLogger(__name__)

def _session(s: Any, participant_id: int, task_index: int | None
             ) -> tuple[ParticipantRow, StudyRow, TaskSessionRow] | None:
    """The participant, study and task session a job is about, if the participant is still at that task."""
    found = repo.get_participant_with_study(s, participant_id=participant_id)
    if found is None or task_index is None:
        return None
    participant, study = found
    ts = current_task(s, participant)
    if ts is None or ts.task_index != task_index:
        return None
    return participant, study, ts


def settle(ctx: Context, job: job_rows.ClaimedJob) -> None:
    """Place the demonstration's stored objects with the robot and store the labels it reports."""
    step = (job.payload["step_kind"], job.payload["step_index"])
    with ctx.db.read() as s:
        found = _session(s, job.participant_id, job.task_index)
        if found is None:
            return
        _participant, _study, ts = found
        if position_of(ts.state_json)[:2] != step or placements.settled(ts):
            return
        placed, reported = list(ts.demo_placed), max(0, len(ts.demo_trace) - 1)
    key = robot_key_of(job)
    placements.sync_robot_table(ctx.robot, key, placed, reported=reported)
    trace = ctx.robot.trace(key)
    if trace is None or len(trace) < len(placed) + 1:
        raise RuntimeError(f"the robot reported {0 if trace is None else len(trace)} states for {len(placed)} "
                           "placements: expected one more state than placements")
    with ctx.db.write() as s:
        repo.lock_participant_id(s, participant_id=job.participant_id)
        found = _session(s, job.participant_id, job.task_index)
        if found is None:
            return
        participant, study, ts = found
        if position_of(ts.state_json)[:2] != step or ts.demo_placed[: len(placed)] != placed:
            return  # the session moved on meanwhile (a later job settles what is stored now)
        a = Action(ctx, s, participant, study, None, None)
        # trace covers the objects placed above: a placement stored meanwhile gets its labels from its own job
        if not placements.record_labels(a, ts, trace, step[0], step[1]):
            return
        repo.commit(s)
    ctx.notifier.publish(job.participant_id)


def work_out(ctx: Context, job: job_rows.ClaimedJob) -> None:
    """Work the stored execution out with the robot and store its plan (its clock starts now)."""
    want = (job.payload["kind"], job.payload["index"], job.payload["events"])
    with ctx.db.read() as s:
        found = _session(s, job.participant_id, job.task_index)
        if found is None:
            return
        participant, _study, ts = found
        ex = ts.execution
        if not _awaits_plan(ex, want):
            return
        rid = RecordingId(participant.uid, ts.task_index, ex["kind"], ex["index"])
        speed = executions.speed_of(ex)
    key = robot_key_of(job)
    planned = executions.plan(ctx, key, rid, list(want[2]), speed)
    files = ctx.store.finished(rid)  # its files, for a store every host reaches (none for local files)
    if files and not any(f.name.endswith(VISER_SUFFIX) for f in files):
        raise RuntimeError(f"the robot left no .viser file of {rid.name}: expected it with the .npz and .json")
    with ctx.db.write() as s:
        repo.lock_participant_id(s, participant_id=job.participant_id)
        found = _session(s, job.participant_id, job.task_index)
        if found is None:
            return
        participant, study, ts = found
        ex = ts.execution
        if not _awaits_plan(ex, want):
            return
        ts.execution = stored = {**ex, "plan": planned, "started_at": utcnow().isoformat()}
        recording_rows.add_files(s, files)  # with the plan: any host that reads the plan can serve the motion
        a = Action(ctx, s, participant, study, None, None)
        a.enqueue(FINISH_EXECUTION, ts.task_index, {"kind": ex["kind"], "index": ex["index"]},
                  due_in=executions.duration(stored))
        repo.commit(s)
    ctx.notifier.publish(job.participant_id)  # the page shows the robot moving, caption and all
    executions.announce(ctx, job.participant_id, stored)
    ctx.runtime.wake()


def _awaits_plan(ex: dict[str, Any] | None, want: tuple[Any, Any, Any]) -> TypeGuard[dict[str, Any]]:
    """Whether the stored execution is the one the job is for, still running and still without a plan."""
    return (ex is not None and ex["status"] == "running" and ex.get("plan") is None
            and (ex["kind"], ex["index"], ex["events"]) == want)


def finish_execution(ctx: Context, job: job_rows.ClaimedJob) -> None:
    """Record the execution as finished once its stored clock says so (again later if it is not over yet)."""
    want = (job.payload["kind"], job.payload["index"])
    with ctx.db.write() as s:
        repo.lock_participant_id(s, participant_id=job.participant_id)
        found = _session(s, job.participant_id, job.task_index)
        if found is None:
            return
        participant, study, ts = found
        ex = ts.execution
        if ex is None or ex["status"] != "running" or (ex["kind"], ex["index"]) != want or ex.get("plan") is None:
            return  # finished already, assessed, or not worked out yet (its work_out job finishes it)
        if not sync_execution(ctx, s, participant, ts):
            a = Action(ctx, s, participant, study, None, None)
            left = executions.duration(ex) - (utcnow() - executions.started_at(ex)).total_seconds()
            a.enqueue(FINISH_EXECUTION, ts.task_index, dict(job.payload), due_in=left)
        repo.commit(s)
    # No notice: the page was told at the stored end already (announce), and showed the finish then.


def plan_ahead(ctx: Context, job: job_rows.ClaimedJob) -> None:
    """Plan the robot's next turn now, and have a robot that records work its execution out ahead."""
    with ctx.db.read() as s:
        found = _session(s, job.participant_id, job.task_index)
        if found is None:
            return
        participant, study, ts = found
        if ts.state_json != job.payload["state"] or ts.execution is not None:
            return
        state_json, task_index = ts.state_json, ts.task_index
        uid, speed = participant.uid, float(study.robot_speed or 1.0)
    if position_of(state_json)[0] not in ROBOT_TURNS:
        return
    key = robot_key_of(job)
    state = session_of(state_json)
    exact = seam.path_of(state.config.task) == "exact"

    def plan(on_learner_thread: bool) -> None:
        step = ctx.planner.step(state_json)
        if on_learner_thread and step.kind == "test":  # the final belief's MAP, for the debriefing (a minute at ten)
            c = state.config
            _ = seam.belief_after(c.task, c.prior, c.flip_rate, core.learning_verdicts(state)).map_mask
        if ctx.robot.works_in_background and step.robot_execution is not None:
            rid = RecordingId(uid, task_index, step.kind, step.index)
            if not on_learner_thread:  # a job runner holds the table's lock already
                executions.plan(ctx, key, rid, list(step.robot_execution.events), speed)
                return
            with ctx.runtime.table_lock(job.participant_id, job.task_index):  # one job of a table at a time
                executions.plan(ctx, key, rid, list(step.robot_execution.events), speed)

    # Past five objects a plan takes seconds to minutes: on the learner's thread, so that no job runner (and no
    # other participant's placement or execution) waits for it. If it is lost (a restart), the request that
    # starts the execution makes it (services.teaching.start_execution, outside any transaction).
    if exact and ctx.runtime.think(_logged(lambda: plan(on_learner_thread=True))) is not None:
        return
    plan(on_learner_thread=False)


def _logged(call: Callable[[], None]) -> Callable[[], None]:
    """call, with a failure logged (a plan made ahead is a courtesy: the execution's request makes it otherwise)."""
    def run() -> None:
        try:
            call()
        except Exception:  # noqa: BLE001 - see docstring
            log.exception("planning a robot turn ahead failed; the request that starts it plans it instead")
    return run


def robot_key_of(job: job_rows.ClaimedJob) -> str:
    """The robot table key of a job's participant and task (the format of services.state.robot_key)."""
    return table_key(job.participant_id, job.task_index)


HANDLERS: dict[str, Handler] = {SETTLE: settle, WORK_OUT: work_out, FINISH_EXECUTION: finish_execution,
                                PLAN_AHEAD: plan_ahead}

