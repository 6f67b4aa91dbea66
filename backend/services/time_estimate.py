"""How long a participant has left: the study's screens ahead, each the participant's own time (the model's
allowance scaled by their measured pace so far) plus the robot's (its measured seconds per object moved)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from .guidance import (INTRO_SECONDS, OBJECTS_PER_EXECUTION, PLACEMENT_SECONDS, QUESTIONNAIRE_SECONDS,
                       THINK_SECONDS)

# The participant's own time on the screens before the tasks (reading an information sheet, the instructions).
READING_SECONDS = {"consent": 90.0, "instructions": 60.0, "quiz": 45.0}
DEMO_OBJECTS = 5  # a demonstration places every object unless this participant's own ones say otherwise
PACE_LIMITS = (0.15, 5.0)  # a pace outside these is a measurement accident (a reload, a pause), not a pace
# The events that end a screen: the next screen starts when one is stored.
SCREEN_ENDS = ("consent", "instructions_read", "quiz", "demonstration", "assessment")


@dataclass(frozen=True)
class Screen:
    """One screen ahead of or behind the participant: its own allowance (seconds) and objects the robot moves."""

    own_seconds: float
    robot_objects: float
    kind: str


@dataclass(frozen=True)
class Timeline:
    """What the participant's events say so far (times in seconds since they joined)."""

    screen_start: float  # when the current screen began
    robot_seconds: float  # robot motion watched so far (executions and their replays)
    robot_objects: int  # objects the robot moved in those executions
    demo_objects: list[int]  # objects placed in each finished demonstration


def screens(step_counts: list[list[tuple[str, int]]], *, quiz: bool, questionnaire: bool,
            demo_objects: float) -> list[Screen]:
    """The study's screens in order for one participant: step_counts per task in their order, [(kind, n)]."""
    out = [Screen(READING_SECONDS["consent"], 0, "consent"), Screen(READING_SECONDS["instructions"], 0, "instructions")]
    if quiz:
        out.append(Screen(READING_SECONDS["quiz"], 0, "quiz"))
    for counts in step_counts:
        first = True
        for kind, n in counts:
            for _ in range(n):
                objects = demo_objects if kind in ("practice", "demonstration") else OBJECTS_PER_EXECUTION
                # A task's introduction is read on its first step's screen.
                out.append(Screen(THINK_SECONDS[kind] + (INTRO_SECONDS if first else 0.0), objects, kind))
                first = False
    if questionnaire:
        out.append(Screen(QUESTIONNAIRE_SECONDS, 0, "questionnaire"))
    return out


def timeline(events: list[Any], joined: datetime) -> Timeline:
    """The timeline of a participant's events (rows with kind, created_at, payload, step_kind, step_index)."""
    def at(e: Any) -> float:
        created = e.created_at if e.created_at.tzinfo else e.created_at.replace(tzinfo=joined.tzinfo)
        return (created - joined).total_seconds()

    start, robot, moved = 0.0, 0.0, 0
    demos: list[int] = []
    began: dict[tuple[Any, ...], float] = {}
    lasted: dict[tuple[Any, ...], float] = {}
    for e in events:
        step = (e.task_index, e.step_kind, e.step_index)
        if e.kind == "execution_started":
            began[step] = at(e)
        elif e.kind == "execution_finished" and step in began:
            lasted[step] = max(0.0, at(e) - began[step])
            robot += lasted[step]
            moved += len((e.payload or {}).get("events") or [])
        elif e.kind == "replay_watched":
            robot += lasted.get(step, 0.0)  # a replay plays the same recording again
        if e.kind == "demonstration":
            demos.append(len((e.payload or {}).get("placed") or []))
        if e.kind in SCREEN_ENDS and not (e.kind == "quiz" and not (e.payload or {}).get("passed")):
            start = at(e)
    return Timeline(start, robot, moved, demos)


def seconds_left(plan: list[Screen], done: int, line: Timeline, now: float, *, speed: float,
                 placed_here: int = 0) -> float:
    """Seconds left from `now` (seconds since joining) with the participant `done` screens into `plan`.

    The pace is the participant's own time on the screens done (their time minus the robot's) over the model's
    allowance for them; the robot's seconds per object are its measured ones (the model's before any)."""
    per_object = (line.robot_seconds / line.robot_objects if line.robot_objects
                  else PLACEMENT_SECONDS / max(speed, 0.1))
    done_plan = plan[:done]
    allowance = sum(s.own_seconds for s in done_plan)
    robot_done = sum(line.demo_objects) * per_object  # the robot placing what the participant chose
    own = line.screen_start - line.robot_seconds - robot_done
    low, high = PACE_LIMITS
    pace = min(high, max(low, own / allowance)) if allowance > 0 and own > 0 else 1.0
    ahead = plan[done:]
    if not ahead:
        return 0.0
    here, rest = ahead[0], ahead[1:]
    on_screen = max(0.0, now - line.screen_start)
    left_here = max(0.0, here.own_seconds * pace - on_screen) + max(0.0, here.robot_objects - placed_here) * per_object
    return left_here + sum(s.own_seconds * pace + s.robot_objects * per_object for s in rest)
