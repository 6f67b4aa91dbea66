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


# A browser walk's recorded events (tests/browser/test_participant.py, laptop, machine at load average 4): seconds
# since joining, the event, and its payload's counts. The walker keeps to a quarter of each screen's allowance; the
# robot's speed is 3.
RECORDED_WALK = [(23.08, "consent", {}), (38.20, "instructions_read", {}),
                 (38.69, "quiz", {"passed": False}), (49.61, "quiz", {"passed": True}),
                 (81.88, "demonstration", {"placed": ["x"] * 4}),
                 (83.29, "execution_started", {}), (93.68, "execution_finished", {"events": ["x"] * 4}),
                 (99.67, "assessment", {}), (130.06, "questionnaire", {})]
# When each screen appeared (seconds since joining) and how many screens of the plan were done then.
RECORDED_STEPS = [("instructions", 23.1, 1), ("quiz", 38.2, 2), ("task introduction", 49.66, 3),
                  ("query", 82.83, 4), ("questionnaire", 99.79, 5)]
RECORDED_END = 130.13


def test_on_a_recorded_browser_walk_the_estimate_is_within_a_fifth_of_the_time_left_at_every_step() -> None:
    """The estimate the page would have shown on each screen after the first (before any screen is done the
    participant's pace is unknown and the model's is used), from the walk's own recorded events."""
    counts = [[("practice", 0), ("demonstration", 1), ("query", 1), ("test", 0)]]
    for name, at, done in RECORDED_STEPS:
        seen = [Event(kind, t, payload, 0, "query" if kind.startswith("execution") else "demonstration", 0)
                for t, kind, payload in RECORDED_WALK if t <= at]
        line = te.timeline(seen, JOINED)
        demos = line.demo_objects
        plan = te.screens(counts, quiz=True, questionnaire=True,
                          demo_objects=sum(demos) / len(demos) if demos else te.DEMO_OBJECTS)
        estimate = te.seconds_left(plan, done, line, at, speed=3.0)
        actual = RECORDED_END - at
        assert estimate == pytest.approx(actual, rel=0.2), f"{name}: {estimate:.0f} s for {actual:.0f} s"
