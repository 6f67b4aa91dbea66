"""Teaching steps: demonstrations, robot executions (queries and tests) and their assessments."""

from __future__ import annotations

from typing import Any

from ..core import session as core
from ..core.domain import get_domain
from ..db import repository as repo
from ..db.tables import TaskSessionRow, utcnow
from ..errors import Conflict, InvalidInput
from ..recording_store import RecordingId
from . import executions, placements
from .context import Context
from .outcomes import code_to_show, outcome_of
from .planning import ROBOT_TURNS, position_of, session_of
from .study_objects import study_objects
from .runtime import FINISH_EXECUTION, WORK_OUT
from .state import (
    Action,
    Expect,
    act,
    require_stage,
    robot_key,
    save_recording,
    session_config,
    sync_execution,
    task_sequence,
)


def begin_task(a: Action, task_index: int) -> None:
    a.participant.stage = "task"
    a.participant.task_index = task_index
    config = session_config(a.study, a.participant, task_index)
    repo.add_task_session(a.s, participant_id=a.participant.id, task_index=task_index,
                          state_json=core.start(config).to_json())
    task = a.study.tasks[task_index]
    a.log("task_started", {"task": task["key"], "ground_truth": task["ground_truth"], "protocol": config.protocol,
                           "seed": config.seed}, task_index=task_index)


def _teaching(a: Action, expect: Expect, kinds: tuple[str, ...]) -> tuple[TaskSessionRow, core.SessionState, core.Step]:
    """The current task session and step (unplanned); Conflict unless the step is one of kinds and matches expect."""
    require_stage(a, "task")
    ts = repo.get_task_session(a.s, participant_id=a.participant.id, task_index=a.participant.task_index)
    assert ts is not None
    state = session_of(ts.state_json)
    step = core.Step(*core.position(state))
    here = f"{step.kind} {step.index + 1} of {step.total} in task {a.participant.task_index + 1}"
    if expect.task_index is not None and expect.task_index != a.participant.task_index:
        raise Conflict(f"this request is for task {expect.task_index + 1}, but the session is at {here}")
    if (expect.step_kind is not None and expect.step_kind != step.kind) or (
        expect.step_index is not None and expect.step_index != step.index
    ):
        want = (f"{expect.step_kind or step.kind} "
                f"{(expect.step_index if expect.step_index is not None else step.index) + 1}")
        raise Conflict(f"this request is for {want}, but the session is at {here}")
    if step.kind not in kinds:
        raise Conflict(f"the session is at {here}; this action needs a {' or '.join(kinds)} step")
    return ts, state, step


def place_object(ctx: Context, token: str, *, obj: str, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """During a practice trial or demonstration, the participant places one object on the table (the robot's
    labels follow: services.placements)."""
    def run(a: Action) -> None:
        ts, _state_, step = _teaching(a, expect, ("practice", "demonstration"))
        objects = study_objects(a.study)
        if obj not in objects:
            raise InvalidInput(f"object: {obj!r} is not an object of this study; expected one of {', '.join(objects)}")
        if obj in ts.demo_placed:
            raise Conflict(f"the {obj} is already on the table; a placed object cannot be placed again")
        try:
            placements.place(a, ts, obj, step.kind, step.index)
        except ValueError as exc:
            raise Conflict(f"the robot could not place the {obj}: {exc}") from exc

    return act(ctx, token, "place", {"object": obj, **expect.__dict__}, key, run)


def finish_demonstration(ctx: Context, token: str, *, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """End the practice trial or demonstration (stopping early is allowed: Task 2 needs it)."""
    placements.wait_settled(ctx, token)  # outside any transaction: the runtime stores the robot's last labels

    def run(a: Action) -> None:
        ts, state, step = _teaching(a, expect, ("practice", "demonstration"))
        if not placements.settled(ts):
            raise Conflict("the robot has not reported the table after every placement yet; try again in a moment")
        # Nothing placed: the trace is the cleared table alone (no robot was asked, so none has reported it).
        trace = [list(labels) for labels in ts.demo_trace] or [sorted(get_domain(state.config.task).labels(()))]
        new_state = core.observe(state, step.kind, trace)
        a.log("demonstration", {"placed": list(ts.demo_placed), "trace": trace},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        table = robot_key(a.participant, ts.task_index)
        if ts.demo_placed:
            participant, task_index, kind, index = a.participant, ts.task_index, step.kind, step.index
            placed = list(ts.demo_placed)

            def save() -> None:  # the robot may have lost the table (a restart): rebuilt quietly first
                placements.sync_robot_table(a.ctx.robot, table, placed)
                save_recording(a.ctx, participant, task_index, kind, index)

            a.after(save)
        a.after(lambda: a.ctx.robot.release(table))
        ts.demo_placed, ts.demo_trace = [], []
        _advance(a, ts, new_state)

    return act(ctx, token, "finish", dict(expect.__dict__), key, run)


def start_execution(ctx: Context, token: str, *, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """The robot carries out the current query or test execution (starting it twice is harmless)."""
    _plan_outside_transactions(ctx, token)

    def run(a: Action) -> None:
        ts, state, step = _teaching(a, expect, ("query", "test"))
        ex = ts.execution
        if ex is not None and (ex["kind"], ex["index"]) == (step.kind, step.index):
            sync_execution(a.ctx, a.s, a.participant, ts)
            return  # a second click on "run": the same execution is already under way or done
        step = a.ctx.planner.step(ts.state_json)
        assert step.robot_execution is not None
        events = list(step.robot_execution.events)
        rid = RecordingId(a.participant.uid, ts.task_index, step.kind, step.index)
        robot = robot_key(a.participant, ts.task_index)
        speed = float(a.study.robot_speed or 1.0)  # the recorded motion plays at the study's speed
        ts.execution = started = {"kind": step.kind, "index": step.index, "events": events, "status": "running",
                                  "trace": None, "p_acceptable": step.p_acceptable,
                                  **executions.begin(a.ctx, robot, rid, events, speed)}
        where = {"kind": step.kind, "index": step.index}
        if started["plan"] is None:
            a.enqueue(WORK_OUT, ts.task_index, {**where, "events": events})
        else:
            pid = a.participant.id
            a.enqueue(FINISH_EXECUTION, ts.task_index, where, due_in=executions.duration(started))
            a.after(lambda: executions.announce(a.ctx, pid, started))
        a.log("execution_started", {"events": events, "p_acceptable": step.p_acceptable},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        sync_execution(a.ctx, a.s, a.participant, ts)

    return act(ctx, token, "execute", dict(expect.__dict__), key, run)


def _plan_outside_transactions(ctx: Context, token: str) -> None:
    """The current robot turn's plan, made (or waited for, if a plan_ahead job is making it) before the action's
    write transaction: past five objects a plan takes seconds, and no transaction may wait that long. The action
    then finds it made (Planner caches it); if the session moved meanwhile, the action plans its own state."""
    with ctx.db.read() as s:
        found = repo.get_participant_and_study(s, token=token) if token else None
        if found is None or found[0].stage != "task":
            return
        ts = repo.get_task_session(s, participant_id=found[0].id, task_index=found[0].task_index)
        state_json = None if ts is None or ts.execution is not None else ts.state_json
    if state_json is not None and position_of(state_json)[0] in ROBOT_TURNS:
        ctx.planner.step(state_json)


def assess_execution(ctx: Context, token: str, *, acceptable: bool | None, expect: Expect,
                     key: str | None = None, shown_fraction: float | None = None) -> dict[str, Any]:
    """The participant's verdict on the robot's finished execution (required for queries), with how much of its
    recorded motion the page had played (shown_fraction, 0-1; None: not reported)."""
    def run(a: Action) -> None:
        ts, state, step = _teaching(a, expect, ("query", "test"))
        ex = ts.execution
        if ex is None or (ex["kind"], ex["index"]) != (step.kind, step.index):
            raise Conflict(f"the robot has not started {step.kind} {step.index + 1} yet; start its execution first")
        sync_execution(a.ctx, a.s, a.participant, ts)
        ex = ts.execution
        assert ex is not None  # sync_execution only ever replaces it
        if ex["status"] != "finished":
            raise Conflict(f"the robot is still carrying out {step.kind} {step.index + 1}; "
                           "assess it once the execution has finished")
        if step.kind == "query" and acceptable is None:
            raise InvalidInput("a query needs an assessment: acceptable must be true or false")
        new_state = core.observe(state, step.kind, ex["trace"], acceptable)
        a.log("assessment", {"acceptable": acceptable, "events": ex["events"], "trace": ex["trace"],
                             "p_acceptable": ex.get("p_acceptable"), "shown_fraction": shown_fraction,
                             "replays": int(ex.get("replays", 0))},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        ts.execution = None
        table = robot_key(a.participant, ts.task_index)
        a.after(lambda: a.ctx.robot.release(table))
        _advance(a, ts, new_state)

    return act(ctx, token, "assess", {"acceptable": acceptable, "shown_fraction": shown_fraction, **expect.__dict__},
               key, run)


def _advance(a: Action, ts: TaskSessionRow, new_state: core.SessionState) -> None:
    """Store the core's new state; after the last step of a task, go to the next task or the questionnaire."""
    ts.state_json = new_state.to_json()
    if new_state.phase in ROBOT_TURNS:
        a.plan_ahead = ts.state_json
    if new_state.phase != "done":
        return
    a.log("task_finished", {}, task_index=ts.task_index)
    table = robot_key(a.participant, ts.task_index)
    a.after(lambda: a.ctx.robot.close(table))  # the next task has its own table (and view)
    sequence = task_sequence(a.study, a.participant)
    position = sequence.index(ts.task_index)
    if position + 1 < len(sequence):
        begin_task(a, sequence[position + 1])
    elif a.study.questionnaire:
        a.participant.stage = "questionnaire"
    else:
        complete(a)


def complete(a: Action) -> None:
    a.participant.stage = "done"
    a.participant.finished_at = utcnow()
    a.participant.completion_code = code_to_show(a.study, outcome_of(a.participant) or "completed")
    a.log("completed", {"completion_code": a.participant.completion_code,
                        "attention_failed": a.participant.attention_failed})
