"""The participant's 3D view: starting it, clicks in it, robot activity, and the one-tab rule."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, NamedTuple

from ..errors import Conflict, InvalidInput
from ..recording_store import RecordingId
from ..robot import ViewAddress
from ..db import repository as repo
from . import executions
from .context import Context
from .placements import sync_robot_table
from .planning import position_of
from .state import Action, Expect, act, current_task, participant_and_study, robot_key, unknown_token
from .teaching import _teaching as teaching_step  # the same step check as the other teaching actions
from .teaching import place_object

log = logging.getLogger(__name__)


def prepare_viewer(ctx: Context, token: str) -> bool:
    """Whether the participant's current step has a 3D view (a task under way and a robot that shows one).

    A browser already showing the table is readied for this step here (its table, and clicks for a
    demonstration); a new browser is connected when the page's viewer opens its websocket (open_viewer)."""
    with ctx.db.read() as s:
        participant, _study = participant_and_study(s, token)  # an unknown token is refused whatever the robot
        ts = current_task(s, participant)
        if not ctx.robot.shows_view or ts is None:
            return False
        key = robot_key(participant, ts.task_index)
    if ctx.robot.has_view(key):
        return open_viewer(ctx, token) is not None
    return True


def open_viewer(ctx: Context, token: str) -> ViewAddress | None:
    """Where the participant's browser connects to the 3D view of the current step, or None (no task, or a robot
    without views).

    The view shows the stored state of the step: the robot's table is rebuilt from the stored placements
    first (the robot forgets its tables on a restart), under the table's runtime lock so that no placement
    job changes it meanwhile. During a practice trial or demonstration a click on a waiting object is queued
    to the runtime and carried out by place_object, the same code path as POST /me/placements.
    """
    with ctx.db.read() as s:
        participant, study_row = participant_and_study(s, token)  # an unknown token is refused whatever the robot
        if not ctx.robot.shows_view:
            return None
        ts = current_task(s, participant)
        if ts is None:
            return None
        kind, index, _ = position_of(ts.state_json)
        demonstrating = kind in ("practice", "demonstration")
        key, pid, task_index = robot_key(participant, ts.task_index), participant.id, ts.task_index
        speed = float(study_row.robot_speed or 1.0)
    robot = ctx.robot
    robot.set_speed(key, speed)
    with ctx.runtime.table_lock(pid, task_index):
        with ctx.db.read() as s:  # read again under the lock: a placement job may have run meanwhile
            participant, _study = participant_and_study(s, token)
            ts = current_task(s, participant)
            placed = list(ts.demo_placed) if ts is not None and demonstrating else []
        sync_robot_table(robot, key, placed)
    on_click: Callable[[str], None] | None = None
    if demonstrating:
        expect = Expect(task_index, kind, index)

        def on_click(obj: str) -> None:  # a viser thread: only queue it
            ctx.runtime.submit(lambda: _place_clicked(ctx, token, key, obj, expect))
    # Robot turns are shown by playing the execution's recording in the browser (current_motion).
    return robot.open_view(key, on_click)


def participant_uid_of(ctx: Context, token: str) -> str:
    """The participant's random uid (it names their recordings) for their token (NotAuthenticated if none has it)."""
    with ctx.db.read() as s:
        participant, _study = participant_and_study(s, token)
        return participant.uid


class Motion(NamedTuple):
    """The recording the browser plays for the current step, and how often it was asked to play it again."""

    recording: RecordingId
    replays: int


def current_motion(ctx: Context, token: str) -> Motion | None:
    """The recording the browser plays for the current step: its robot execution, once started and recorded."""
    with ctx.db.read() as s:
        participant, _study = participant_and_study(s, token)
        ts = current_task(s, participant)
        if ts is None or ts.execution is None:
            return None
        ex = ts.execution
        kind, index, _ = position_of(ts.state_json)
        recorded = ex.get("recorded") or (ex.get("plan") or {}).get("viewable")
        if (ex["kind"], ex["index"]) != (kind, index) or not recorded:
            return None
        return Motion(RecordingId(participant.uid, ts.task_index, kind, index), int(ex.get("replays", 0)))


def _place_clicked(ctx: Context, token: str, key: str, obj: str, expect: Expect) -> None:
    """A click in the 3D view, on the runtime's action queue; one that came too late for its step is dropped."""
    try:
        place_object(ctx, token, obj=obj, expect=expect)
    except (Conflict, InvalidInput) as exc:
        log.info("click on %s not placed: %s", obj, exc.message)
    except Exception:  # noqa: BLE001 - a busy database: the participant clicks again (the page says so)
        log.warning("click on %s could not be placed now", obj, exc_info=True)
    finally:
        ctx.robot.click_done(key)


def replay_execution(ctx: Context, token: str, *, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """Play the robot's finished execution again in the browser (its recorded .viser file, no re-planning) and log
    that it was watched; every process says the robot is busy until the replay has played (robot_activity)."""
    replayed: dict[str, Any] = {}

    def run(a: Action) -> None:
        ts, _state, step = teaching_step(a, expect, ("query", "test"))
        ex = ts.execution
        if ex is None or (ex["kind"], ex["index"]) != (step.kind, step.index) or ex["status"] != "finished":
            raise Conflict(f"there is nothing to watch again yet: {step.kind} {step.index + 1} has not finished; "
                           "watch again once the robot has finished")
        if not (ex.get("plan") or {}).get("viewable"):
            raise Conflict("this robot has no 3D view, so there is no recorded motion to watch again; "
                           "answer from the objects listed")
        if executions.replaying(ex):
            raise Conflict("the robot's attempt is being shown again already; wait until it has finished")
        ts.execution = replayed["ex"] = executions.replay(ex)
        replayed["pid"] = a.participant.id
        a.log("replay_watched", {"events": ex["events"], "replay": ts.execution["replays"]},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        a.after(lambda: executions.announce(ctx, replayed["pid"], replayed["ex"]))

    return act(ctx, token, "replay", dict(expect.__dict__), key, run)


def next_robot_change(ctx: Context, token: str) -> float | None:
    """Seconds until the participant's execution reaches its next stored action end (or its replay ends), if any."""
    with ctx.db.read() as s:
        row = repo.poll_row(s, token=token)
    if row is None:
        raise unknown_token()
    return executions.next_change_in(row.execution)


def claim_tab(ctx: Context, token: str, tab_id: str, *, takeover: bool = False) -> dict[str, Any]:
    """Hold (or renew) the one-tab lease of the participant's page; held is False while another tab holds it."""
    held = ctx.tabs.claim(_participant_id(ctx, token), tab_id, takeover=takeover)
    return {"held": held, "lease_seconds": ctx.tabs.seconds}


def release_tab(ctx: Context, token: str, tab_id: str) -> None:
    """The tab is going away (reload or close): let the next one take over at once."""
    ctx.tabs.release(_participant_id(ctx, token), tab_id)


def _participant_id(ctx: Context, token: str) -> int:
    """The participant's number, from the small poll query (no ORM objects)."""
    with ctx.db.read() as s:
        row = repo.poll_row(s, token=token)
    if row is None:
        raise unknown_token()
    return row.participant_id
