"""A demonstration's placements: the participant's choice is stored at once, the robot's report comes after.

`POST /me/placements` stores the object (event `place`) and, for a robot that takes time (the MuJoCo arm
needs about 80 ms of physics per placement), a `settle` job in the same transaction, and answers. The
runtime then has the robot place every stored object it has not placed yet (rebuilding its table from the
stored placements if it lost it: a restart, another process) and stores the labels it reports (event
`placed`), retrying until that succeeds (services.background). Until then the state's
`demonstration.settled` is false and the page keeps its buttons off. Finishing a demonstration waits for
the labels, outside any transaction.

A robot that places at once (the trace robot, no physics) reports in the request itself, so its `place` and
`placed` events share one transaction.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from ..db.tables import TaskSessionRow
from ..robot import Labels, Robot
from .context import Context
from .runtime import SETTLE
from .state import Action, participant_and_study, current_task, robot_key

SETTLE_WAIT_SECONDS = 30.0  # a placement's physics takes about 0.1 s; the runtime retries a failed store
SETTLE_POLL_SECONDS = 0.05


def settled(ts: TaskSessionRow) -> bool:
    """Whether the robot has reported the table after every stored placement."""
    return not ts.demo_placed or len(ts.demo_trace) >= len(ts.demo_placed) + 1


def sync_robot_table(robot: Robot, key: str, placed: Sequence[str], *, reported: int | None = None) -> None:
    """Make the robot's table hold exactly the stored placements: place the missing ones if what it holds is a
    prefix of them, else rebuild it (a restart, another process, a table freed while idle, a new demonstration).

    A rebuild restores the first `reported` placements (default: all) without showing their motion, since the
    participant has seen them already; the rest are placed as new, with their motion."""
    held = robot.placed(key)
    if held is None and not placed:
        return  # nothing to hold: a robot shows a table it does not hold as cleared
    if held is not None and len(held) <= len(placed) and tuple(placed[: len(held)]) == held:
        for obj in placed[len(held):]:
            robot.place(key, obj)
        return
    quiet = len(placed) if reported is None else max(0, min(reported, len(placed)))
    robot.restore(key, placed[:quiet])
    for obj in placed[quiet:]:
        robot.place(key, obj)


def record_labels(a: Action, ts: TaskSessionRow, trace: Sequence[Labels], step_kind: str, step_index: int) -> bool:
    """Store the labels the robot reported for stored placements that have none yet (one `placed` event each, the
    initial table first); True if anything was stored."""
    placed = list(ts.demo_placed)
    known = len(ts.demo_trace)
    new = [sorted(trace[i]) for i in range(known, min(len(trace), len(placed) + 1))]
    for i, labels in enumerate(new, start=known):
        if i > 0:
            a.log("placed", {"object": placed[i - 1], "labels": labels, "placed": placed[:i]},
                  task_index=ts.task_index, step_kind=step_kind, step_index=step_index)
    if new:
        ts.demo_trace = [*ts.demo_trace, *new]
    return bool(new)


def place(a: Action, ts: TaskSessionRow, obj: str, step_kind: str, step_index: int) -> None:
    """Store one placement (already checked) and have the robot report it: a settle job for a robot that takes
    time, or in the request for one that places at once (ValueError if it cannot place the object)."""
    before = list(ts.demo_placed)
    ts.demo_placed = [*before, obj]
    a.log("place", {"object": obj, "placed": list(ts.demo_placed)},
          task_index=ts.task_index, step_kind=step_kind, step_index=step_index)
    robot, key = a.ctx.robot, robot_key(a.participant, ts.task_index)
    if robot.works_in_background:
        a.enqueue(SETTLE, ts.task_index, {"step_kind": step_kind, "step_index": step_index})
        return
    if not ts.demo_trace:
        robot.reset(key)
    sync_robot_table(robot, key, before)  # the trace robot shows nothing: a rebuild costs nothing
    robot.place(key, obj)
    trace = robot.trace(key)
    if trace is not None:
        record_labels(a, ts, trace, step_kind, step_index)


def wait_settled(ctx: Context, token: str, timeout: float = SETTLE_WAIT_SECONDS) -> None:
    """Until the robot has reported every stored placement of the participant's demonstration (or timeout), in
    read transactions only; the action that needs it checks again."""
    deadline = time.monotonic() + timeout
    while True:
        with ctx.db.read() as s:
            participant, _study = participant_and_study(s, token)
            ts = current_task(s, participant)
            if ts is None or settled(ts):
                return
        if time.monotonic() >= deadline:
            return
        ctx.runtime.wake()
        time.sleep(SETTLE_POLL_SECONDS)
