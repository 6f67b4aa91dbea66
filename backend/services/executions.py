"""A robot execution as the database holds it: its plan (the labels after each action, when each action
ends) and its start time. Any app process tells how far an execution has got from these alone, so no
execution lives in a process: a participant's requests may go to any process, and one that is killed
mid-execution loses nothing (the execution's clock keeps running in the database).

A robot that needs time to work an execution out (the MuJoCo robot simulates and records it: about a
second) does so in a durable background job (services.background, work_out): the request that starts the
execution stores it without a plan, with the job, and answers at once; the plan is stored when ready, and
its clock starts then. If the process working it out dies, the job's lease runs out and a live process
works it out again (executions are deterministic, so the result is the same). Times are UTC wall-clock
times: app processes on several hosts need synchronised clocks (NTP).

An execution carries the study's playback speed (`speed`, robot_speed 1-3): the browser's .viser file plays
at that speed and the stored action times are divided by it, so the stored clock and the playback agree
(saved recordings keep real time). The page is told of each action's end and of the finish: the process
that stores a plan schedules notices on its runtime (announce), and the page's event stream wakes itself at
the next stored action end as well (next_change_in), in case that process has gone. "Watch it again" replays
the recorded file in the browser; its start is stored too, so every process says the robot is busy until it
has played.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from ..db.tables import utcnow
from ..robot import ExecutionPlan
from ..recording_store import RecordingId
from .context import Context, aware

log = logging.getLogger(__name__)


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


def begin(ctx: Context, key: str, rid: RecordingId, events: list[str], speed: float = 1.0) -> dict[str, Any]:
    """The fields of a starting execution: its plan now (a quick robot), or none yet (a work_out job makes it)."""
    now = utcnow().isoformat()
    if ctx.robot.works_in_background:
        return {"plan": None, "recorded": True, "started_at": now, "speed": speed}
    return {"plan": plan(ctx, key, rid, events, speed), "started_at": now, "speed": speed}


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


ANNOUNCE_LAG_SECONDS = 0.02  # a notice just after the action's end, so that the state read then shows it


def announce(ctx: Context, participant_id: int, execution: dict[str, Any] | None) -> None:
    """Publish a change notice at each of the execution's remaining stored action ends (its finish included), or
    at the end of its replay, from the runtime's scheduler; the page then shows the next caption or the answer.

    The page's event stream also wakes itself at the next stored action end (next_change_in), so a notice lost
    with a process that died only comes a moment later."""
    if execution is None or execution.get("plan") is None:
        return

    def tick() -> None:
        ctx.notifier.publish(participant_id)
        schedule()

    def schedule() -> None:
        wait = next_change_in(execution)
        if wait is not None:
            ctx.runtime.call_later(max(0.0, wait) + ANNOUNCE_LAG_SECONDS, tick)

    schedule()
