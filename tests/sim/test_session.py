"""SceneSession: background executions, refusals before motion, real-time replay only when watched."""

import time

import pytest

from tableteach.sim import PlacementError
from tableteach.sim.session import SceneSession, SessionBusyError


def test_execution_runs_in_the_background_and_returns_the_trace():
    session = SceneSession(seed=0, view=False)
    try:
        session.run(["dinner_plate", "small_plate"])
        trace = session.wait(timeout=30)
        assert trace == [frozenset(), {"dinner_plate"}, {"dinner_plate", "small_plate"}]
        assert not session.busy
        assert session.placed == ("dinner_plate", "small_plate")
    finally:
        session.close()


def test_invalid_requests_are_refused_before_anything_moves():
    session = SceneSession(seed=0, view=False)
    try:
        session.run(["knife"])
        session.wait(timeout=30)
        for bad in (["fork", "spoon"], ["fork", "fork"], ["knife"]):
            with pytest.raises(PlacementError):
                session.run(bad)
        assert session.placed == ("knife",)
    finally:
        session.close()


def test_watched_execution_replays_in_real_time_with_caption_and_clicks_disabled():
    session = SceneSession(seed=0, view=True, realtime=True, speed=4.0)
    try:
        started = time.perf_counter()
        session.run(["bowl"], drop=["bowl"])
        time.sleep(0.3)
        assert session.busy
        assert session.view._caption.text == "The robot is placing the bowl"
        with pytest.raises(SessionBusyError):
            session.run(["knife"])
        trace = session.wait(timeout=30)
        elapsed = time.perf_counter() - started
        assert elapsed >= 0.9 * session.recording.duration / 4.0
        assert trace == [frozenset(), frozenset()]  # dropped
        assert "bowl" not in session.view.clickable
        assert session.view._caption.visible is False
    finally:
        session.close()


def test_unwatched_view_fast_forwards(monkeypatch: pytest.MonkeyPatch):
    from tableteach.sim import session as session_module

    played: list[object] = []
    monkeypatch.setattr(session_module, "play_frames", lambda *args, **kwargs: played.append(args))
    session = SceneSession(seed=0, view=True)  # nobody connected: no real-time replay
    try:
        session.run(["fork", "knife"])
        trace = session.wait(timeout=120)
        assert played == []  # nothing paced at wall-clock speed
        assert trace[-1] == frozenset({"fork", "knife"}) and session.recording.duration > 0
    finally:
        session.close()


def test_close_stops_a_running_execution_promptly():
    session = SceneSession(seed=0, view=True, realtime=True)
    session.run(["dinner_plate", "bowl"])
    time.sleep(0.5)
    session.close()  # returns once the execution's thread has stopped
    assert not session.busy
    # paced at wall-clock speed, two placements take over 10 s: closing stopped it before the second was done
    assert len(session.trace) < 3


def test_reset_restores_table_a_and_clickability():
    session = SceneSession(seed=0, view=True)
    try:
        session.run(["fork"])
        session.wait(timeout=30)
        session.reset(seed=1)
        assert session.trace == [frozenset()] and session.placed == ()
        assert "fork" in session.view.clickable
    finally:
        session.close()
