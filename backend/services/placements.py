"""A demonstration's placements: the participant's choice is stored at once, the robot's report comes after.

`POST /me/placements` stores the object (event `place`) and answers. The robot then places it: the MuJoCo
arm needs about 80 ms of physics per placement, which inside the request made placements the slowest action
under load. When the robot is done, a second transaction stores the table's labels (event `placed`) and
tells the page. Until then the state's `demonstration.settled` is false, and the page keeps its buttons
off (it does so anyway while the arm's motion is shown, about 5 s).

A robot that places at once (the trace robot) reports in the request itself, so its `place` and `placed`
events share one transaction. Placements of one table are simulated in the order they were stored: a
request placing the next object first waits for the previous one (a scripted teacher placing back to
back), and finishing a demonstration waits for all of them, so its trace is always complete. A robot
that has lost the table (a restart, another process) rebuilds it from the stored placements.
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import Future

from ..db import repository as repo
from ..db.tables import TaskSessionRow
from .context import Context
from .planning import position_of
from .state import Action, robot_key

log = logging.getLogger(__name__)

WAIT_SECONDS = 30.0  # a placement's physics takes about 0.1 s; one still running after this has gone wrong


def sync_table(a: Action, ts: TaskSessionRow) -> None:
    """Make the robot's table match the stored placements; the first one of a demonstration clears it."""
    key = robot_key(a.participant, ts.task_index)
    if not ts.demo_trace:
        a.ctx.placements.wait(key, WAIT_SECONDS)
        ts.demo_trace = [sorted(a.ctx.robot.reset(key))]
    else:
        rebuild_table(a.ctx, key, ts.demo_placed)


def rebuild_table(ctx: Context, key: str, placed: list[str]) -> None:
    """Wait for the table's placements under way; if the robot's table still differs (it was lost), rebuild it."""
    ctx.placements.wait(key, WAIT_SECONDS)
    if ctx.robot.placed(key) != tuple(placed):
        ctx.robot.reset(key)
        for obj in placed:
            ctx.robot.place(key, obj)


def store_labels(a: Action, ts: TaskSessionRow, step_kind: str, step_index: int) -> bool:
    """Store the labels the robot reported for placements it has finished (one `placed` event each); True once
    every stored placement has its labels."""
    key = robot_key(a.participant, ts.task_index)
    placed, trace = a.ctx.robot.placed(key), a.ctx.robot.trace(key)
    if placed is None or trace is None or tuple(placed) != tuple(ts.demo_placed[: len(placed)]):
        return len(ts.demo_trace) == len(ts.demo_placed) + 1  # a lost table: the next request rebuilds it
    known, done = len(ts.demo_trace) - 1, min(len(placed), len(trace) - 1)
    new = [sorted(trace[i + 1]) for i in range(known, done)]
    for i, labels in enumerate(new, start=known):
        a.log("placed", {"object": placed[i], "labels": labels, "placed": list(placed[: i + 1])},
              task_index=ts.task_index, step_kind=step_kind, step_index=step_index)
    if new:
        ts.demo_trace = [*ts.demo_trace, *new]
    return len(ts.demo_trace) == len(ts.demo_placed) + 1


def place_after_commit(a: Action, ts: TaskSessionRow, obj: str) -> None:
    """Have the robot place obj once the request has committed, then store its labels in a transaction of their own.

    The queue holds only the physics: a request waiting for the table (sync_table) may hold the participant's
    row lock, which the storing transaction takes, so that runs on a thread of its own afterwards.
    """
    ctx, key, token, task_index = a.ctx, robot_key(a.participant, ts.task_index), a.participant.token, ts.task_index

    def physics() -> None:
        try:
            ctx.robot.place(key, obj)
        except Exception:
            log.exception("the robot failed to place the %s at table %s; the table is rebuilt on the next request",
                          obj, key)
            raise

    def store(done: Future[None]) -> None:
        if done.exception() is None:
            threading.Thread(target=_store_reported, args=(ctx, token, key, task_index), name="store-labels",
                             daemon=True).start()

    a.after_commit.append(lambda: ctx.placements.submit(key, physics).add_done_callback(store))


def _store_reported(ctx: Context, token: str, key: str, task_index: int) -> None:
    """The background transaction: the labels of the placements the robot has finished, if still current (for the
    step the session is at now: a late thread may find the next demonstration under way, its table the robot's)."""
    try:
        with ctx.db.write() as s:
            repo.lock_participant(s, token=token)
            found = repo.get_participant_and_study(s, token=token)
            if found is None:
                return
            participant, study = found
            if participant.stage != "task" or participant.task_index != task_index:
                return
            ts = repo.get_task_session(s, participant_id=participant.id, task_index=task_index)
            if ts is None or not ts.demo_trace:
                return
            a = Action(ctx, s, participant, study, None, None)
            step_kind, step_index, _total = position_of(ts.state_json)
            before = len(ts.demo_trace)
            store_labels(a, ts, step_kind, step_index)
            if len(ts.demo_trace) == before:
                return
            repo.commit(s)
            participant_id = participant.id
        ctx.notifier.publish(participant_id)
    except Exception:  # noqa: BLE001 - the labels are stored by the next request that needs them (finish)
        log.exception("storing the robot's labels for table %s failed; finishing the demonstration stores them", key)
