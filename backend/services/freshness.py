"""Cheap polls: an entity tag per participant state and per robot activity, so that a page's poll that finds
nothing new is answered "304 Not Modified" from one small query, without building the state.

A state's tag names the versions of every row it is built from (the participant, the study, the current task's
session; each bumped by every update) and the one thing that changes by the clock alone: whether a running
execution has reached its stored end. The state's clock-driven numbers (idle seconds, seconds left) are as of
the answer that carried the tag; the page counts on from there until the next change."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from ..db import repository as repo
from ..db.repository import PollRow
from . import executions
from .context import Context
from .etags import digest_tag, state_tag
from .state import unknown_token, participant_and_study, state_view, table_key


def current_state_tag(ctx: Context, token: str) -> str | None:
    """The participant's state tag now (None for an unknown token: the full read answers that with 401)."""
    with ctx.db.read() as s:
        row = repo.poll_row(s, token=token)
    return None if row is None else state_tag(row)


def tagged_state(ctx: Context, token: str) -> tuple[dict[str, Any], str]:
    """The participant's state and its tag (the state's own `etag`)."""
    with ctx.db.read() as s:
        participant, study = participant_and_study(s, token)
        state = state_view(s, participant, study)
    return state, state["etag"]


def robot_activity(ctx: Context, token: str) -> dict[str, Any]:
    """What the participant's robot is doing now: moving, a caption, and how many views are connected."""
    return _activity(ctx, _poll_row(ctx, token))


@dataclass(frozen=True)
class ChangeSnapshot:
    """What a change event says, from one read: the robot's activity, the state's tag (the page reads its state
    only when that differs from the tag it holds) and the seconds to the execution's next stored action end."""

    robot: dict[str, Any]
    state_tag: str
    next_change_in: float | None


def change_snapshot(ctx: Context, token: str) -> ChangeSnapshot:
    """The participant's change snapshot now (one query)."""
    row = _poll_row(ctx, token)
    return ChangeSnapshot(_activity(ctx, row), state_tag(row), executions.next_change_in(row.execution))


def _poll_row(ctx: Context, token: str) -> PollRow:
    with ctx.db.read() as s:
        row = repo.poll_row(s, token=token)
    if row is None:
        raise unknown_token()
    return row


def _activity(ctx: Context, row: PollRow) -> dict[str, Any]:
    robot = ctx.robot
    in_task = row.stage == "task"
    activity = robot.activity(table_key(row.participant_id, row.task_index)) if in_task else None
    out = {"view": robot.shows_view, "moving": bool(activity and activity.moving),
           "caption": activity.caption if activity else "", "watchers": activity.watchers if activity else 0}
    ex = row.execution
    if ex is not None and ex["status"] == "running":
        # An execution's progress is in the database, whichever process started it.
        progress = executions.progress(ex)
        out.update(moving=not progress.finished, caption=progress.caption)
    elif ex is not None and executions.replaying(ex):
        out.update(moving=True, caption=executions.REPLAY_CAPTION)
    return out


def activity_tag(activity: dict[str, Any]) -> str:
    """The entity tag of a robot activity answer (it is small, so its content is the tag)."""
    return digest_tag("robot", json.dumps(activity, sort_keys=True, separators=(",", ":")))
