"""A robot execution as the database holds it: its plan (the labels after each action, when each action
ends) and its start time. Any app process tells how far an execution has got from these alone, so no
execution lives in a process: a participant's requests may go to any process, and one that is killed
mid-execution loses nothing (the execution's clock keeps running in the database).

Times are UTC wall-clock times; app processes on several hosts need synchronised clocks (NTP).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from ..db.tables import utcnow
from ..sim.recordings import RecordingId
from .context import Context, aware


@dataclass(frozen=True)
class ExecutionProgress:
    """How far a stored execution has got: actions shown so far, the labels up to then, and whether it is over."""

    shown: int
    trace: list[list[str]]
    finished: bool
    caption: str  # e.g. "The robot is placing the bowl (2 of 4)"; empty once finished


def plan(ctx: Context, key: str, rid: RecordingId, events: list[str]) -> dict[str, Any]:
    """Work the execution out with the robot (saving its recording) and return the plan to store with it."""
    worked = ctx.robot.plan_execution(key, events, rid.name)
    return {"trace": [sorted(labels) for labels in worked.trace], "action_ends": list(worked.action_ends),
            "viewable": worked.viewable}


def prepare_ahead(ctx: Context, key: str, participant_id: int, task_index: int, state_json: str) -> None:
    """Once the robot's next turn is planned, let the robot work its execution out in the background (the MuJoCo
    robot simulates and records it), so that starting the execution seconds later costs the request nothing."""
    prepare = getattr(ctx.robot, "prepare", None)
    if prepare is None:
        return

    def use(step: Any) -> None:
        if step.robot_execution is not None:
            rid = RecordingId(participant_id, task_index, step.kind, step.index)
            prepare(key, list(step.robot_execution.events), rid.name)

    ctx.planner.then(state_json, use)


def started_at(execution: dict[str, Any]) -> datetime:
    """When the execution's motion started (its plan's clock)."""
    start = aware(datetime.fromisoformat(execution["started_at"]))
    assert start is not None
    return start


def progress(execution: dict[str, Any], now: datetime | None = None) -> ExecutionProgress:
    """The progress of a stored execution that has a plan, at `now` (default: the current time)."""
    stored = execution["plan"]
    ends: list[float] = stored["action_ends"]
    elapsed = ((now or utcnow()) - started_at(execution)).total_seconds()
    shown = sum(1 for end in ends if end <= elapsed)
    events = execution["events"]
    finished = shown == len(events)
    caption = "" if finished else (f"The robot is placing the {events[shown].replace('_', ' ')} "
                                   f"({shown + 1} of {len(events)})")
    return ExecutionProgress(shown, [list(x) for x in stored["trace"][: shown + 1]], finished, caption)
