"""The calibrated time estimate (services.time_estimate): a participant who keeps a steady pace, with a robot
whose speed is measured, is told the time left to within a few per cent at every screen."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from typing import Any

import pytest

from tableteach.services import time_estimate as te

JOINED = datetime(2026, 12, 1, 12, 0, tzinfo=timezone.utc)


@dataclass
class Event:
    kind: str
    seconds: float
    payload: dict[str, Any] = field(default_factory=dict)
    task_index: int | None = None
    step_kind: str | None = None
    step_index: int | None = None

    @property
    def created_at(self) -> datetime:
        return JOINED + timedelta(seconds=self.seconds)


def _walk(pace: float, per_object: float, demo: int, executed: int) -> tuple[list[te.Screen], list[list[Event]]]:
    """A participant through 2 demonstrations, 2 queries and a test, then the questionnaire: the plan, and the
    events stored by the start of each screen."""
    counts = [[("practice", 0), ("demonstration", 2), ("query", 2), ("test", 1)]]
    plan = te.screens(counts, quiz=False, questionnaire=True, demo_objects=demo)
    t, events, seen = 0.0, [], []
    names = {"consent": "consent", "instructions": "instructions_read"}
    for i, screen in enumerate(plan):
        seen.append(list(events))
        step = (0, screen.kind, i)
        if screen.kind == "demonstration":
            t += screen.own_seconds * pace + demo * per_object
            events.append(Event("demonstration", t, {"placed": ["x"] * demo}, *step))
        elif screen.kind in ("query", "test"):
            t += screen.own_seconds * pace / 2
            events.append(Event("execution_started", t, {}, *step))
            t += executed * per_object
            events.append(Event("execution_finished", t, {"events": ["x"] * executed}, *step))
            t += screen.own_seconds * pace / 2
            events.append(Event("assessment", t, {}, *step))
        else:
            t += screen.own_seconds * pace
            events.append(Event(names.get(screen.kind, "questionnaire"), t))
    seen.append(list(events))
    return plan, seen


@pytest.mark.parametrize("pace", [0.3, 1.0, 2.5])
def test_a_steady_participant_is_told_the_time_left_within_a_tenth_once_a_screen_is_done(pace: float) -> None:
    per_object = 1.9  # the robot's motion at 3x
    plan, seen = _walk(pace, per_object, demo=4, executed=4)
    end = seen[-1][-1].seconds
    for done in range(1, len(plan)):
        line = te.timeline(seen[done], JOINED)
        if done >= 3:  # the participant's own demonstrations tell how many objects they place
            plan = te.screens([[("practice", 0), ("demonstration", 2), ("query", 2), ("test", 1)]], quiz=False,
                              questionnaire=True, demo_objects=sum(line.demo_objects) / len(line.demo_objects))
        estimate = te.seconds_left(plan, done, line, line.screen_start, speed=3.0)
        actual = end - line.screen_start
        assert estimate == pytest.approx(actual, rel=0.1), f"screen {done}: {estimate:.0f} s for {actual:.0f} s"


def test_before_anything_is_measured_the_model_is_used_and_nothing_is_left_at_the_end() -> None:
    plan = te.screens([[("demonstration", 1), ("query", 1)]], quiz=True, questionnaire=False, demo_objects=5)
    assert [s.kind for s in plan] == ["consent", "instructions", "quiz", "demonstration", "query"]
    line = te.timeline([], JOINED)
    model = sum(s.own_seconds for s in plan) + (5 + te.OBJECTS_PER_EXECUTION) * te.PLACEMENT_SECONDS
    assert te.seconds_left(plan, 0, line, 0.0, speed=1.0) == pytest.approx(model)
    assert te.seconds_left(plan, len(plan), line, 500.0, speed=1.0) == 0.0
