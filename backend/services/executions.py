"""A robot execution as the database holds it: its plan (the labels after each action, when each action
ends) and its start time. Any app process tells how far an execution has got from these alone, so no
execution lives in a process: a participant's requests may go to any process, and one that is killed
mid-execution loses nothing (the execution's clock keeps running in the database).

A robot that needs time to work an execution out (the MuJoCo robot simulates and records it: about a
second) does so in the background: the request that starts the execution stores it without a plan and
answers at once; the plan is stored when ready, and its clock starts then. If the process working it out
dies, the next process asked about the execution starts working it out in the background, and any
process works it out in the request once PREPARE_GRACE_SECONDS have passed (executions are
deterministic, so the result is the same). Times are UTC wall-clock times: app processes on several
hosts need synchronised clocks (NTP).

An execution carries the study's playback speed (`speed`, robot_speed 1-3): the browser's .viser file plays
at that speed and the stored action times are divided by it, so the stored clock and the playback agree
(saved recordings keep real time). The page is told of each action's end and of the finish: the process
that stores a plan keeps a timer (announce), and the page's event stream wakes itself at the next stored
action end as well (next_change_in), in case that process has gone. "Watch it again" replays the recorded
file in the browser; its start is stored too, so every process says the robot is busy until it has played.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from ..db import repository as repo
from ..db.tables import utcnow
from ..robot import ExecutionPlan
from ..sim.recordings import RecordingId
from .context import Context, aware

log = logging.getLogger(__name__)
PREPARE_GRACE_SECONDS = 30.0
STORE_ATTEMPTS = 5


@dataclass(frozen=True)
class ExecutionProgress:
    """How far a stored execution has got: actions shown so far, the labels up to then, and whether it is over."""

    shown: int
    trace: list[list[str]]
    finished: bool
    caption: str  # e.g. "The robot is placing the bowl (2 of 4)"; empty once finished


def _stored(worked: ExecutionPlan) -> dict[str, Any]:
    return {"trace": [sorted(labels) for labels in worked.trace], "action_ends": list(worked.action_ends),
            "viewable": worked.viewable}


def speed_of(execution: dict[str, Any]) -> float:
    """The playback speed stored with an execution (1.0 for one stored before speeds were)."""
    return float(execution.get("speed") or 1.0)


def plan(ctx: Context, key: str, rid: RecordingId, events: list[str], speed: float = 1.0) -> dict[str, Any]:
    """Work the execution out with the robot now (saving its recording) and return the plan to store with it."""
    return _stored(ctx.robot.plan_execution(key, events, rid.name, speed=speed))


def works_in_background(ctx: Context) -> bool:
    """Whether the robot takes time (the MuJoCo robot): it works executions out, and places a demonstration's
    objects, in the background rather than at once (see services.placements)."""
    return getattr(ctx.robot, "prepare", None) is not None


def begin(ctx: Context, key: str, rid: RecordingId, events: list[str], speed: float = 1.0) -> dict[str, Any]:
    """The fields of a starting execution: its plan now (a quick robot), or none yet and `recorded` (see module)."""
    now = utcnow().isoformat()
    if works_in_background(ctx):
        return {"plan": None, "recorded": True, "started_at": now, "speed": speed}
    return {"plan": plan(ctx, key, rid, events, speed), "started_at": now, "speed": speed}


_storing: set[tuple[int, str]] = set()  # (robot, recording) whose plan this process is waiting to store
_storing_lock = threading.Lock()


def work_out_in_background(ctx: Context, key: str, participant_id: int, rid: RecordingId, events: list[str],
                           speed: float = 1.0) -> None:
    """Have the robot work the stored execution out and store its plan when ready (after the commit; again by
    any process asked about an execution still without a plan, e.g. after the one working it out died)."""
    waiting = (id(ctx.robot), rid.name)
    with _storing_lock:
        if waiting in _storing:
            return
        _storing.add(waiting)
    try:
        future: Future[ExecutionPlan] = ctx.robot.prepare(key, events, rid.name,  # type: ignore[attr-defined]
                                                          speed=speed)
    except Exception:
        with _storing_lock:
            _storing.discard(waiting)
        raise

    def store(done: Future[ExecutionPlan]) -> None:
        try:
            _store_plan(ctx, participant_id, rid, events, done)
        finally:
            with _storing_lock:
                _storing.discard(waiting)

    # Always on a thread of its own: a plan made ahead is done already, and its callback would then run
    # here, in the request, which may still hold the database's write lock (SQLite).
    future.add_done_callback(lambda done: threading.Thread(target=store, args=(done,), name="store-plan",
                                                           daemon=True).start())


def _store_plan(ctx: Context, participant_id: int, rid: RecordingId, events: list[str],
                done: Future[ExecutionPlan]) -> None:
    """Store a plan worked out in the background, unless the execution has moved on or has one already."""
    if done.cancelled() or done.exception() is not None:
        log.warning("working out %s failed; a later request works it out again", rid.name,
                    exc_info=done.exception())
        return
    stored = _stored(done.result())
    for attempt in range(STORE_ATTEMPTS):
        try:
            with ctx.db.write() as s:
                ts = repo.get_task_session(s, participant_id=participant_id, task_index=rid.task_index)
                ex = None if ts is None else ts.execution
                if (ex is None or ex["status"] != "running" or ex.get("plan") is not None
                        or (ex["kind"], ex["index"], ex["events"]) != (rid.step_kind, rid.step_index, events)):
                    return
                assert ts is not None
                ts.execution = stored_ex = {**ex, "plan": stored, "started_at": utcnow().isoformat()}
                repo.commit(s)
            ctx.notifier.publish(participant_id)  # the page shows the robot moving, caption and all
            announce(ctx, participant_id, stored_ex)
            return
        except repo.WriteConflict:
            time.sleep(0.05 * (attempt + 1))  # a participant request stored first; read again
        except Exception:
            log.exception("could not store the plan of %s", rid.name)
            return
    log.warning("gave up storing the plan of %s after %s write conflicts", rid.name, STORE_ATTEMPTS)


def overdue(execution: dict[str, Any], now: datetime | None = None) -> bool:
    """A running execution still without a plan long after it started (whoever was working it out has died)."""
    return (execution.get("plan") is None
            and ((now or utcnow()) - started_at(execution)).total_seconds() > PREPARE_GRACE_SECONDS)


def prepare_ahead(ctx: Context, key: str, participant_uid: str, task_index: int, state_json: str,
                  speed: float = 1.0) -> None:
    """Once the robot's next turn is planned, let the robot work its execution out in the background (the MuJoCo
    robot simulates and records it), so that it is ready, or nearly, when the participant starts it."""
    if not works_in_background(ctx):
        return

    def use(step: Any) -> None:
        if step.robot_execution is not None:
            rid = RecordingId(participant_uid, task_index, step.kind, step.index)
            ctx.robot.prepare(key, list(step.robot_execution.events), rid.name,  # type: ignore[attr-defined]
                              speed=speed)

    ctx.planner.then(state_json, use)


def started_at(execution: dict[str, Any]) -> datetime:
    """When the execution's motion started (its plan's clock), or when it was asked for while it has no plan."""
    return _time(execution["started_at"])


def _time(stored: str) -> datetime:
    """A stored ISO time as an aware UTC datetime."""
    at = aware(datetime.fromisoformat(stored))
    assert at is not None
    return at


GETTING_READY = "The robot is getting ready"


def progress(execution: dict[str, Any], now: datetime | None = None) -> ExecutionProgress:
    """The progress of a stored execution at `now` (default: the current time); none while it has no plan."""
    stored = execution.get("plan")
    if stored is None:
        return ExecutionProgress(0, [], False, GETTING_READY)
    ends: list[float] = stored["action_ends"]
    elapsed = ((now or utcnow()) - started_at(execution)).total_seconds()
    shown = sum(1 for end in ends if end <= elapsed)
    events = execution["events"]
    finished = shown == len(events)
    caption = "" if finished else (f"The robot is placing the {events[shown].replace('_', ' ')} "
                                   f"({shown + 1} of {len(events)})")
    return ExecutionProgress(shown, [list(x) for x in stored["trace"][: shown + 1]], finished, caption)


REPLAY_CAPTION = "Showing the robot's attempt again"


def duration(execution: dict[str, Any]) -> float:
    """Seconds from the start of the execution's motion to its last action's end (0 without a plan)."""
    ends = (execution.get("plan") or {}).get("action_ends") or [0.0]
    return float(ends[-1])


def replay(execution: dict[str, Any]) -> dict[str, Any]:
    """A finished execution with its recorded motion replayed from now (the browser plays it again)."""
    return {**execution, "replays": int(execution.get("replays", 0)) + 1, "replay_started_at": utcnow().isoformat()}


def replaying(execution: dict[str, Any], now: datetime | None = None) -> bool:
    """Whether the browser is still replaying the execution's recorded motion ("Watch it again")."""
    start = execution.get("replay_started_at")
    if start is None:
        return False
    return ((now or utcnow()) - _time(start)).total_seconds() < duration(execution)


def next_change_in(execution: dict[str, Any] | None, now: datetime | None = None) -> float | None:
    """Seconds until the next stored action end (or the end of a replay), or None when nothing is due."""
    if execution is None or execution.get("plan") is None:
        return None
    now = now or utcnow()
    if execution["status"] == "running":
        elapsed = (now - started_at(execution)).total_seconds()
    elif execution.get("replay_started_at") is not None:
        elapsed = (now - _time(execution["replay_started_at"])).total_seconds()
        return (duration(execution) - elapsed) if elapsed < duration(execution) else None
    else:
        return None
    upcoming = [end - elapsed for end in execution["plan"]["action_ends"] if end > elapsed]
    return min(upcoming) if upcoming else None


_announcing: set[tuple[int, str]] = set()  # (participant, start) whose action ends this process will announce
_announcing_lock = threading.Lock()


def announce(ctx: Context, participant_id: int, execution: dict[str, Any] | None) -> None:
    """Publish a change notice at each of the execution's remaining stored action ends (its finish included), or
    at the end of its replay, from a timer in this process; the page then shows the next caption or the answer."""
    if execution is None or execution.get("plan") is None:
        return
    mark = (participant_id, str(execution.get("replay_started_at") or execution["started_at"]))
    with _announcing_lock:
        if mark in _announcing:
            return
        _announcing.add(mark)

    def schedule() -> None:
        wait = next_change_in(execution)
        if wait is None:
            with _announcing_lock:
                _announcing.discard(mark)
            return
        _start_timer(wait, tick)

    def tick() -> None:
        ctx.notifier.publish(participant_id)
        schedule()

    schedule()


ANNOUNCE_LAG_SECONDS = 0.02  # a notice just after the action's end, so that the state read then shows it


def _start_timer(wait: float, then: Any) -> None:
    timer = threading.Timer(max(0.0, wait) + ANNOUNCE_LAG_SECONDS, then)
    timer.daemon = True
    timer.name = "announce-execution"
    timer.start()
