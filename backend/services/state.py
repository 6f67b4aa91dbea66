"""A participant's state as the API shows it, and the action machinery (idempotency, step guards, one commit)."""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..core import session as core
from ..core.domain import DINNER_OBJECTS, get_domain
from ..db import repository as repo
from ..db.tables import ParticipantRow, StudyRow, TaskSessionRow, utcnow
from ..errors import Conflict, NotAuthenticated
from ..sim import recordings
from ..sim.recordings import RecordingId
from . import executions
from .context import Context, app_version, aware, iso
from .guidance import lay_summary, progress, required_objects
from .page_state import extend_state
from .planning import ROBOT_TURNS, position_of, session_of

log = logging.getLogger(__name__)


STAGES = ("consent", "instructions", "quiz", "task", "questionnaire", "done", "withdrawn", "screened_out")
UNDER_WAY = ("consent", "instructions", "quiz", "task", "questionnaire")


def task_sequence(study: StudyRow, participant: ParticipantRow) -> list[int]:
    """The study's task indices in the order this participant does them (counterbalancing)."""
    return list(participant.task_order) if participant.task_order else list(range(len(study.tasks)))


def timed_out(study: StudyRow, participant: ParticipantRow) -> bool:
    """Whether a participant still under way has been idle past the study's timeout."""
    if not study.timeout_minutes or participant.stage not in UNDER_WAY:
        return False
    last = aware(participant.last_activity_at) or utcnow()
    return (utcnow() - last).total_seconds() > study.timeout_minutes * 60


def end_participation(s: Any, participant: ParticipantRow, *, stage: str, reason: str,
                      key: str | None = None, digest: str | None = None) -> None:
    """The participant leaves before the end (withdrawn or screened out); the reason is logged."""
    participant.stage = stage
    participant.end_reason = reason
    participant.finished_at = utcnow()
    repo.append_event(s, participant=participant, kind=stage, app_version=app_version(), payload={"reason": reason},
                      client_event_id=key, request_digest=digest)


def mark_timed_out(s: Any, participant: ParticipantRow) -> None:
    """Screen out a participant idle past the study's timeout; their data stay, flagged."""
    idle_since = aware(participant.last_activity_at)
    end_participation(s, participant, stage="screened_out", reason="timeout")
    participant.last_activity_at = idle_since or participant.last_activity_at  # the timeout is not activity


def robot_key(participant: ParticipantRow, task_index: int) -> str:
    return f"{participant.id}/{task_index}"


def apply_speed(ctx: Context, key: str, study: StudyRow) -> None:
    """Tell a robot that shows motion the study's playback speed for this table (others ignore it)."""
    set_speed = getattr(ctx.robot, "set_speed", None)
    if set_speed is not None:
        set_speed(key, float(study.robot_speed or 1.0))


def save_recording(ctx: Context, participant: ParticipantRow, task_index: int, kind: str, index: int) -> None:
    """Ask the robot to keep this step's motion; a failure is logged, never shown to the participant."""
    try:
        ctx.robot.save_recording(robot_key(participant, task_index),
                                 RecordingId(participant.uid, task_index, kind, index).name)
    except Exception:
        log.exception("could not save the recording of participant %s task %s %s %s", participant.id, task_index,
                      kind, index)


def delete_recordings(ctx: Context, participant: ParticipantRow) -> int:
    """Delete every robot recording of this participant (for erasure); the number of files removed.

    Call it before the participant's row is deleted (it needs participant.uid)."""
    return recordings.delete_recordings(ctx.settings.data_dir, participant.uid)


def session_config(study: StudyRow, participant: ParticipantRow, task_index: int) -> core.SessionConfig:
    return core.SessionConfig(
        task="dinner", prior=study.prior, protocol=participant.condition,
        # The practice trial is there to learn the interface, so only the task this participant does first has one.
        n_practice=study.n_practice if task_sequence(study, participant)[0] == task_index else 0,
        n_demonstrations=study.n_demonstrations, n_queries=study.n_queries, n_tests=study.n_tests,
        criterion=study.criterion, seed=(participant.seed + task_index) % (2**31),
    )


def current_task(s: Any, participant: ParticipantRow) -> TaskSessionRow | None:
    if participant.stage != "task":
        return None
    return repo.get_task_session(s, participant_id=participant.id, task_index=participant.task_index)


def sync_execution(ctx: Context, s: Any, participant: ParticipantRow, ts: TaskSessionRow) -> bool:
    """Record a running execution that has finished by its stored clock; True if the stored state changed.

    The plan and start time are in the database (services.executions), so any process answers alike. An
    execution whose plan is overdue (its process died while working it out) or that was stored without one
    by an older version is worked out here, starting now.
    """
    execution = ts.execution
    if execution is None or execution["status"] != "running":
        return False
    changed = False
    if execution.get("plan") is None:
        if execution.get("recorded") and not executions.overdue(execution):
            return False  # still being worked out in the background
        rid = RecordingId(participant.uid, ts.task_index, execution["kind"], execution["index"])
        execution = {**execution, "plan": executions.plan(ctx, robot_key(participant, ts.task_index), rid,
                                                           execution["events"], executions.speed_of(execution)),
                     "started_at": utcnow().isoformat()}
        ts.execution, changed = execution, True
    progress = executions.progress(execution)
    if not progress.finished:
        return changed
    trace = progress.trace
    ts.execution = {**execution, "status": "finished", "trace": trace, "finished_at": utcnow().isoformat()}
    repo.append_event(
        s, participant=participant, kind="execution_finished", app_version=app_version(),
        task_index=ts.task_index, step_kind=execution["kind"], step_index=execution["index"],
        payload={"events": execution["events"], "trace": trace},
    )
    return True


def state_view(s: Any, participant: ParticipantRow, study: StudyRow, *, replayed: bool = False) -> dict[str, Any]:
    """What a participant (or scripted teacher) sees: stage, current step, robot and questionnaire."""
    out: dict[str, Any] = {
        "participant_id": participant.id,
        "token": participant.token,
        "study_id": study.id,
        "stage": participant.stage,
        "n_events": participant.n_events,
        "objects": list(DINNER_OBJECTS),
        "consent": {"text": study.consent_text, "version": study.consent_version,
                    "given_at": iso(participant.consent_at)},
        "task": None, "step": None, "demonstration": None, "execution": None,
        "questionnaire": None, "completion": None, "quiz": None, "replayed": replayed,
    }
    if participant.stage == "task":
        ts = current_task(s, participant)
        task = study.tasks[participant.task_index]
        sequence = task_sequence(study, participant)
        out["task"] = {"index": participant.task_index, "total": len(study.tasks), "name": task["name"],
                       "instructions": task["instructions"], "key": task["key"],
                       "position": sequence.index(participant.task_index), "required": required_objects(task)}
        if ts is not None:
            kind, index, total = position_of(ts.state_json)
            out["step"] = {"kind": kind, "index": index, "total": total}
            if kind in ("practice", "demonstration"):
                out["demonstration"] = {"placed": list(ts.demo_placed),
                                        "labels": ts.demo_trace[-1] if ts.demo_trace else [],
                                        "trace": list(ts.demo_trace),
                                        # the robot has reported the table after every placement
                                        "settled": len(ts.demo_trace) >= len(ts.demo_placed) + 1
                                        or not ts.demo_placed}
            elif kind in ROBOT_TURNS:
                ex = ts.execution
                if ex is not None and (ex["kind"], ex["index"]) == (kind, index):
                    out["execution"] = {"kind": ex["kind"], "index": ex["index"], "status": ex["status"],
                                        "events": ex["events"], "trace": ex.get("trace"),
                                        "replays": int(ex.get("replays", 0)),
                                        "motion_seconds": executions.duration(ex)}
                else:
                    out["execution"] = {"kind": kind, "index": index, "status": "not_started",
                                        "events": None, "trace": None}
    elif participant.stage == "quiz":
        out["quiz"] = {"items": [{k: item[k] for k in ("id", "text", "options")} for item in study.quiz],
                       "failed_attempts": participant.quiz_failures,
                       "attempts_left": max(0, study.quiz_max_attempts - participant.quiz_failures)}
    elif participant.stage == "questionnaire":
        # An attention check looks like any agreement item: its expected answer stays on the server.
        out["questionnaire"] = [{k: v for k, v in item.items() if k != "expected"} for item in study.questionnaire]
    elif participant.stage == "done":
        out["completion"] = {"code": participant.completion_code, "reason": None,
                             "redirect_url": _completion_url(study, participant.completion_code),
                             "learned": _learned(s, participant)}
    elif participant.end_reason is not None and participant.end_reason != "withdrew":
        # Declined consent, failed the comprehension quiz or timed out: the study's screened-out code.
        code = study.screened_out_code
        out["completion"] = {"code": code, "reason": participant.end_reason,
                             "redirect_url": _completion_url(study, code), "learned": []}
    elif participant.stage == "withdrawn":
        out["completion"] = {"code": None, "reason": participant.end_reason, "redirect_url": None, "learned": []}
    # Progress follows the participant's own task order (counterbalancing): position, not the task's index.
    sequence = task_sequence(study, participant)
    configs = [session_config(study, participant, i) for i in sequence]
    position = sequence.index(participant.task_index) if participant.task_index in sequence else 0
    out["progress"] = progress(configs, participant.stage, position, out["step"],
                               speed=study.robot_speed, questionnaire=bool(study.questionnaire))
    extend_state(out, s, participant, study)  # issue 21's hook: the participant page's extras (page_state.py)
    return out


def _learned(s: Any, participant: ParticipantRow) -> list[dict[str, Any]]:
    """The debriefing: what the robot believes each task is, once the participant has finished."""
    space = get_domain("dinner").clause_space
    out = []
    for ts in repo.task_sessions_of(s, participant_id=participant.id):
        b = core.belief(session_of(ts.state_json))
        out.append({"task_index": ts.task_index, "map_formula": space.text_of(b.map_mask),
                    "map_description": space.describe(b.map_mask),
                    "summary": lay_summary(space.clauses_of(b.map_mask))})
    return out


def _completion_url(study: StudyRow, code: str | None) -> str | None:
    if not study.completion_url:
        return None
    return study.completion_url.replace("{code}", code or "")


def participant_state(ctx: Context, token: str) -> dict[str, Any]:
    """The participant's state; a robot execution that has finished meanwhile is recorded first."""
    with ctx.db.read() as s:
        participant, study = participant_and_study(s, token)
        ts = current_task(s, participant)
        ex = ts.execution if ts is not None else None
        # Only a running execution that has just finished (or needs working out here) is written.
        needs_write = ex is not None and ex["status"] == "running" and (
            executions.progress(ex).finished if ex.get("plan") is not None
            else not ex.get("recorded") or executions.overdue(ex))
        expired = timed_out(study, participant)
        if not needs_write and not expired:
            if ts is not None and ts.execution is None:
                ctx.planner.plan_ahead(ts.state_json)  # e.g. after a restart, before the participant asks
            elif ex is not None and ex["status"] == "running" and ex.get("plan") is None:
                _resume_working_out(ctx, participant, ts.task_index, ex)
            return state_view(s, participant, study)
    try:
        with ctx.db.write() as s:
            participant, study = participant_and_study(s, token)
            if timed_out(study, participant):
                mark_timed_out(s, participant)
                repo.commit(s)
                ctx.notifier.publish(participant.id)
                return state_view(s, participant, study)
            ts = current_task(s, participant)
            if ts is not None and sync_execution(ctx, s, participant, ts):
                stored = ts.execution
                repo.commit(s)
                ctx.notifier.publish(participant.id)
                executions.announce(ctx, participant.id, stored)  # one worked out here: its action ends
            return state_view(s, participant, study)
    except repo.WriteConflict:
        # Another request (the page's poll, another process) recorded the same finish first: show what it stored.
        with ctx.db.read() as s:
            participant, study = participant_and_study(s, token)
            return state_view(s, participant, study)


def _resume_working_out(ctx: Context, participant: ParticipantRow, task_index: int, ex: dict[str, Any]) -> None:
    """An execution still being worked out, perhaps by a process that has died: work it out here too (the robot
    skips it if it is already doing so). Never fails the request that only asked for the state."""
    try:
        executions.work_out_in_background(ctx, robot_key(participant, task_index), participant.id,
                                          RecordingId(participant.uid, task_index, ex["kind"], ex["index"]),
                                          list(ex["events"]), executions.speed_of(ex))
    except Exception:  # noqa: BLE001 - the overdue path in sync_execution works it out in the end
        log.warning("could not resume working out an execution", exc_info=True)


def participant_and_study(s: Any, token: str) -> tuple[ParticipantRow, StudyRow]:
    found = repo.get_participant_and_study(s, token=token) if token else None
    if found is None:
        raise _unknown_token()
    return found


def _unknown_token() -> NotAuthenticated:
    return NotAuthenticated("unknown participant token; use the link you were given (Authorization: Bearer <token>)")


@dataclass
class Expect:
    """Where the client believes the session is; a mismatch (second tab, stale page) is a 409."""

    task_index: int | None = None
    step_kind: str | None = None
    step_index: int | None = None


@dataclass
class Action:
    """One participant request being carried out: its log writes carry the idempotency key."""

    ctx: Context
    s: Any
    participant: ParticipantRow
    study: StudyRow
    key: str | None
    digest: str | None
    n_logged: int = 0
    plan_ahead: str | None = None  # a stored state whose robot turn can be planned once this commits
    after_commit: list[Callable[[], None]] = field(default_factory=list)  # background work once committed

    def log(self, kind: str, payload: dict[str, Any], *, task_index: int | None = None,
            step_kind: str | None = None, step_index: int | None = None) -> None:
        """Append an event; the first one of the request stores the client's key."""
        first = self.n_logged == 0
        self.n_logged += 1
        repo.append_event(
            self.s, participant=self.participant, kind=kind, payload=payload, app_version=app_version(),
            task_index=task_index, step_kind=step_kind, step_index=step_index,
            client_event_id=self.key if first else None, request_digest=self.digest if first else None,
        )


def _digest(action: str, body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps([action, body], sort_keys=True, default=str).encode()).hexdigest()


def act(ctx: Context, token: str, action: str, body: dict[str, Any], key: str | None,
         run: Callable[[Action], None]) -> dict[str, Any]:
    """Run one participant action in a write transaction: replay check, change, log, commit, new state."""
    digest = _digest(action, body)
    with ctx.db.write() as s:
        if token:
            repo.lock_participant(s, token=token)  # one request per participant at a time (PostgreSQL)
        found = repo.get_participant_for_request(s, token=token, client_event_id=key) if token else None
        if found is None:
            raise _unknown_token()
        participant, study, earlier = found
        if earlier is None and action != "withdraw" and timed_out(study, participant):
            mark_timed_out(s, participant)
            repo.commit(s)
            ctx.notifier.publish(participant.id)
            raise Conflict("you were away longer than this study allows, so it has ended for you",
                           state=state_view(s, participant, study))
        if earlier is not None:
            if earlier.request_digest == digest:
                return state_view(s, participant, study, replayed=True)
            raise Conflict(f"Idempotency-Key {key!r} was already used for a different request "
                           f"({earlier.kind}); use a new key for a new action",
                           state=state_view(s, participant, study))
        try:
            action = Action(ctx, s, participant, study, key, digest)
            run(action)
            repo.commit(s)
            ctx.notifier.publish(participant.id)
            for then in action.after_commit:
                then()
            if action.plan_ahead is not None:
                ctx.planner.plan_ahead(action.plan_ahead)
                ts_index = participant.task_index
                executions.prepare_ahead(ctx, robot_key(participant, ts_index), participant.uid, ts_index,
                                         action.plan_ahead, float(study.robot_speed or 1.0))
            return state_view(s, participant, study)
        except Conflict as exc:
            conflict = exc
        except repo.WriteConflict as exc:
            conflict = Conflict(f"another request for this participant was stored first; here is the current "
                                f"state ({exc})")
    # Outside the write transaction (and its lock): the current state for the 409 answer.
    if conflict.state is None:
        conflict.state = _reload_state(ctx, token)
    raise conflict


def _reload_state(ctx: Context, token: str) -> dict[str, Any] | None:
    try:
        return participant_state(ctx, token)
    except Exception:  # the state is a courtesy in an error answer; never mask the error itself
        log.exception("could not load state for a conflict answer")
        return None


def require_stage(a: Action, stage: str) -> None:
    if a.participant.stage != stage:
        raise Conflict(f"this action belongs to the {stage} stage, but the participant is at the "
                       f"{a.participant.stage} stage")
