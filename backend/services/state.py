"""A participant's state as the API shows it, and the action machinery (idempotency, step guards, one commit)."""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import timedelta
from typing import Any

from ..core import learner_seam as seam
from ..core import session as core
from ..core.domain import get_domain
from ..db import repository as repo
from ..db.tables import ParticipantRow, StudyRow, TaskSessionRow, utcnow
from ..db import jobs as job_rows
from ..db import recording_rows
from ..errors import Conflict, NotAuthenticated
from ..recording_store import RecordingId
from . import executions, outcomes
from .context import Context, app_version, aware, iso
from .etags import state_tag_of
from .runtime import HELD_KINDS, HELD_SECONDS, PLAN_AHEAD
from .guidance import lay_summary, progress, required_objects
from .page_state import extend_state
from .planning import ROBOT_TURNS, position_of, session_of
from .study_objects import study_objects, task_name

log = logging.getLogger(__name__)


STAGES = ("consent", "instructions", "quiz", "task", "questionnaire", "done", "withdrawn", "screened_out")
UNDER_WAY = ("consent", "instructions", "quiz", "task", "questionnaire")


def task_sequence(study: StudyRow, participant: ParticipantRow) -> list[int]:
    """The study's task indices in the order this participant does them (counterbalancing)."""
    return list(participant.task_order) if participant.task_order else list(range(len(study.tasks)))


def timed_out(study: StudyRow, participant: ParticipantRow) -> bool:
    """Whether a participant still under way has been idle past the study's timeout; after a change of the limit
    only idleness since the change counts (lowering it never screens out at once those already idle)."""
    if not study.timeout_minutes or participant.stage not in UNDER_WAY:
        return False
    idle_since = aware(participant.last_activity_at) or utcnow()
    changed = aware(study.timeout_changed_at)
    if changed is not None and changed > idle_since:
        idle_since = changed
    return (utcnow() - idle_since).total_seconds() > study.timeout_minutes * 60


def end_participation(s: Any, participant: ParticipantRow, *, stage: str, reason: str,
                      key: str | None = None, digest: str | None = None) -> None:
    """The participant leaves before the end (withdrawn or screened out); the reason is logged."""
    participant.stage = stage
    participant.end_reason = reason
    participant.finished_at = utcnow()
    repo.append_event(s, participant=participant, kind=stage, app_version=app_version(), payload={"reason": reason},
                      client_event_id=key, request_digest=digest)


def mark_timed_out(s: Any, participant: ParticipantRow) -> bool:
    """Screen out a participant idle past the study's timeout (false, and nothing changes, if they are not): their
    data stay, flagged, they are given the study's time-out code, and they finished at their last activity."""
    study = repo.get_study(s, study_id=participant.study_id)
    if study is None or not timed_out(study, participant):
        return False
    idle_since = aware(participant.last_activity_at)
    participant.completion_code = outcomes.code_to_show(study, "timeout")
    end_participation(s, participant, stage="screened_out", reason="timeout")
    if idle_since is not None:  # the time-out is not activity: they left when they last acted
        participant.last_activity_at = participant.finished_at = idle_since
    return True


def goal_picture_path(study_id: str, task_index: int) -> str:
    """Where the page loads the goal picture of a task of a study with its own objects (web/pages.py serves it)."""
    return f"/study/{study_id}/goal/{task_index}.svg"


def table_key(participant_id: int, task_index: int | None) -> str:
    """The robot's table key of a participant's task: "<participant id>/<task index>" (notify.participant_of_key)."""
    return f"{participant_id}/{task_index}"


def robot_key(participant: ParticipantRow, task_index: int) -> str:
    """The robot's table key of this participant's task."""
    return table_key(participant.id, task_index)


def apply_speed(ctx: Context, key: str, study: StudyRow) -> None:
    """Tell the robot the study's playback speed for this table (a robot that shows no motion ignores it)."""
    ctx.robot.set_speed(key, float(study.robot_speed or 1.0))


def save_recording(ctx: Context, participant: ParticipantRow, task_index: int, kind: str, index: int) -> None:
    """Ask the robot to keep this step's motion; a failure is logged, never shown to the participant."""
    rid = RecordingId(participant.uid, task_index, kind, index)
    try:
        ctx.robot.save_recording(robot_key(participant, task_index), rid.name)
        keep_recording(ctx, participant.id, rid)
    except Exception:
        log.exception("could not save the recording of participant %s task %s %s %s", participant.id, task_index,
                      kind, index)


def keep_recording(ctx: Context, participant_id: int, rid: RecordingId) -> None:
    """Add a saved step's files to the store every host reaches (a short transaction; nothing for local files),
    unless the participant has left meanwhile (erasure forgets their files)."""
    files = ctx.store.finished(rid)
    if not files:
        return
    with ctx.db.write() as s:
        repo.lock_participant_id(s, participant_id=participant_id)
        participant = s.get(ParticipantRow, participant_id, populate_existing=True)
        if participant is None or participant.stage in ("erased", "withdrawn"):
            return
        recording_rows.add_files(s, files)
        repo.commit(s)


def delete_recordings(ctx: Context, participant: ParticipantRow) -> int:
    """Delete every robot recording of this participant (for erasure); the number of files removed.

    Call it before the participant's row is deleted (it needs participant.uid)."""
    return ctx.store.delete_participant(participant.uid)


def session_config(study: StudyRow, participant: ParticipantRow, task_index: int) -> core.SessionConfig:
    return core.SessionConfig(
        task=task_name(study), prior=study.prior, protocol=participant.condition,
        # The practice trial is there to learn the interface, so only the task this participant does first has one.
        n_practice=study.n_practice if task_sequence(study, participant)[0] == task_index else 0,
        n_demonstrations=study.n_demonstrations, n_queries=study.n_queries, n_tests=study.n_tests,
        criterion=study.criterion, seed=(participant.seed + task_index) % (2**31),
        flip_rate=float(study.flip_rate or 0.0),  # the noise-aware learner, if the study uses it
    )


def current_task(s: Any, participant: ParticipantRow) -> TaskSessionRow | None:
    if participant.stage != "task":
        return None
    return repo.get_task_session(s, participant_id=participant.id, task_index=participant.task_index)


def sync_execution(ctx: Context, s: Any, participant: ParticipantRow, ts: TaskSessionRow) -> bool:
    """Record a running execution that has finished by its stored clock; True if the stored state changed.

    The plan and start time are in the database (services.executions), so any process answers alike; an
    execution still without a plan is being worked out by a work_out job (services.background)."""
    execution = ts.execution
    if execution is None or execution["status"] != "running" or execution.get("plan") is None:
        return False
    progress = executions.progress(execution)
    if not progress.finished:
        return False
    trace = progress.trace
    ts.execution = {**execution, "status": "finished", "trace": trace, "finished_at": utcnow().isoformat()}
    repo.append_event(
        s, participant=participant, kind="execution_finished", app_version=app_version(),
        task_index=ts.task_index, step_kind=execution["kind"], step_index=execution["index"],
        payload={"events": execution["events"], "trace": trace},
    )
    return True


def shown_execution(ex: dict[str, Any]) -> dict[str, Any]:
    """An execution as the page sees it now: one whose stored clock has run out shows as finished, with its
    trace, even before the runtime has recorded the finish (a read never writes)."""
    out = {"kind": ex["kind"], "index": ex["index"], "status": ex["status"], "events": ex["events"],
           "trace": ex.get("trace"), "replays": int(ex.get("replays", 0))}
    if ex["status"] == "running" and ex.get("plan") is not None:
        progress = executions.progress(ex)
        if progress.finished:
            out.update(status="finished", trace=progress.trace)
    return out


def state_view(s: Any, participant: ParticipantRow, study: StudyRow, *, replayed: bool = False) -> dict[str, Any]:
    """What a participant (or scripted teacher) sees: stage, current step, robot and questionnaire."""
    out: dict[str, Any] = {
        "participant_id": participant.id,
        "token": participant.token,
        "study_id": study.id,
        "stage": participant.stage,
        "n_events": participant.n_events,
        "objects": list(study_objects(study)),
        "consent": {"text": study.consent_text, "version": study.consent_version,
                    "given_at": iso(participant.consent_at)},
        "task": None, "step": None, "demonstration": None, "execution": None,
        "questionnaire": None, "completion": None, "quiz": None, "replayed": replayed,
    }
    if study.objects:  # a study with its own objects: how each looks (the page words its text for any task)
        out["own_objects"] = [{k: o[k] for k in ("name", "shape", "colour")} for o in study.objects]
    ts = None
    if participant.stage == "task":
        ts = current_task(s, participant)
        task = study.tasks[participant.task_index]
        sequence = task_sequence(study, participant)
        out["task"] = {"index": participant.task_index, "total": len(study.tasks), "name": task["name"],
                       "instructions": task["instructions"], "key": task["key"],
                       "position": sequence.index(participant.task_index),
                       "required": required_objects(task, task_name(study))}
        if study.objects:  # the study's own objects: the page draws them and shows this goal picture
            out["task"]["goal_picture"] = goal_picture_path(study.id, participant.task_index)
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
                    out["execution"] = {**shown_execution(ex), "motion_seconds": executions.duration(ex)}
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
    elif participant.end_reason is not None:
        # Declined consent, failed the quiz, timed out or withdrew: the code given for that outcome (outcomes.py).
        code = participant.completion_code
        redirect = _completion_url(study, code) if code or participant.end_reason != "withdrew" else None
        out["completion"] = {"code": code, "reason": participant.end_reason, "redirect_url": redirect,
                             "learned": []}
    # Progress follows the participant's own task order (counterbalancing): position, not the task's index.
    sequence = task_sequence(study, participant)
    configs = [session_config(study, participant, i) for i in sequence]
    position = sequence.index(participant.task_index) if participant.task_index in sequence else 0
    out["progress"] = progress(configs, participant.stage, position, out["step"],
                               speed=study.robot_speed, questionnaire=bool(study.questionnaire))
    extend_state(out, s, participant, study)  # issue 21's hook: the participant page's extras (page_state.py)
    out["etag"] = state_tag_of(participant, study, ts)  # GET /me's ETag: a change event with it brings nothing new
    return out


def _learned(s: Any, participant: ParticipantRow) -> list[dict[str, Any]]:
    """The debriefing: what the robot believes each task is, once the participant has finished."""
    out = []
    for ts in repo.task_sessions_of(s, participant_id=participant.id):
        session = session_of(ts.state_json)
        space = get_domain(session.config.task).clause_space
        c = session.config
        b = seam.belief_after(c.task, c.prior, c.flip_rate, core.learning_verdicts(session))
        out.append({"task_index": ts.task_index, "map_formula": space.text_of(b.map_mask),
                    "map_description": space.describe(b.map_mask),
                    "summary": lay_summary(space.clauses_of(b.map_mask))})
    return out


def _completion_url(study: StudyRow, code: str | None) -> str | None:
    if not study.completion_url:
        return None
    return study.completion_url.replace("{code}", code or "")


def participant_state(ctx: Context, token: str, *, replayed: bool = False) -> dict[str, Any]:
    """The participant's state, read only (the runtime records finishes and time-outs; see services.background)."""
    with ctx.db.read() as s:
        participant, study = participant_and_study(s, token)
        return state_view(s, participant, study, replayed=replayed)


def participant_and_study(s: Any, token: str) -> tuple[ParticipantRow, StudyRow]:
    found = repo.get_participant_and_study(s, token=token) if token else None
    if found is None:
        raise unknown_token()
    return found


def unknown_token() -> NotAuthenticated:
    return NotAuthenticated("unknown participant token; use the link you were given (Authorization: Bearer <token>)")


@dataclass
class Expect:
    """Where the client believes the session is; a mismatch (second tab, stale page) is a 409."""

    task_index: int | None = None
    step_kind: str | None = None
    step_index: int | None = None


@dataclass
class Action:
    """One participant request being carried out: its log writes carry the idempotency key; what it needs done
    after its transaction (jobs, robot calls, notices) is collected here and run once it has committed."""

    ctx: Context
    s: Any
    participant: ParticipantRow
    study: StudyRow
    key: str | None
    digest: str | None
    n_logged: int = 0
    plan_ahead: str | None = None  # a stored state whose robot turn a plan_ahead job plans once this commits
    effects: list[Callable[[], None]] = field(default_factory=list)  # run after the commit, outside the transaction
    wake_runtime: bool = False  # jobs were added: the runtime looks for them at once after the commit

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

    def enqueue(self, kind: str, task_index: int, payload: dict[str, Any], *, due_in: float = 0.0) -> None:
        """Record a background job in this action's transaction (services.background says what each kind does); one
        of runtime.HELD_KINDS is held for this process for a moment, as it needs this process's state."""
        job_rows.add_job(self.s, kind=kind, participant_id=self.participant.id, task_index=task_index,
                         payload=payload, due_at=utcnow() + timedelta(seconds=max(0.0, due_in)),
                         held_for=self.ctx.runtime.owner if kind in HELD_KINDS else None, held_seconds=HELD_SECONDS)
        self.wake_runtime = True

    def after(self, effect: Callable[[], None]) -> None:
        """Run effect once the action has committed, outside its transaction (a failure is logged)."""
        self.effects.append(effect)


def _digest(action: str, body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps([action, body], sort_keys=True, default=str).encode()).hexdigest()


def act(ctx: Context, token: str, action: str, body: dict[str, Any], key: str | None,
        run: Callable[[Action], None]) -> dict[str, Any]:
    """Run one participant action as one unit of work: replay check, change, log and jobs in one write
    transaction and one commit; then, with the transaction ended, the notice, the runtime's wake-up, the
    action's effects and the new state (read in a transaction of its own)."""
    digest = _digest(action, body)
    conflict: Conflict | None = None
    done: Action | None = None
    replayed = expired = False
    with ctx.db.write() as s:
        if token:
            repo.lock_participant(s, token=token)  # one request per participant at a time (PostgreSQL)
        found = repo.get_participant_for_request(s, token=token, client_event_id=key) if token else None
        if found is None:
            raise unknown_token()
        participant, study, earlier = found
        participant_id = participant.id
        if earlier is None and action != "withdraw" and timed_out(study, participant):
            mark_timed_out(s, participant)
            repo.commit(s)
            expired = True
        elif earlier is not None:
            if earlier.request_digest == digest:
                replayed = True
            else:
                conflict = Conflict(f"Idempotency-Key {key!r} was already used for a different request "
                                    f"({earlier.kind}); use a new key for a new action")
        else:
            try:
                a = Action(ctx, s, participant, study, key, digest)
                run(a)
                if a.plan_ahead is not None:
                    a.enqueue(PLAN_AHEAD, participant.task_index, {"state": a.plan_ahead})
                repo.commit(s)
                done = a
            except Conflict as exc:
                conflict = exc
            except repo.WriteConflict as exc:
                conflict = Conflict(f"another request for this participant was stored first; here is the current "
                                    f"state ({exc})")
    # The transaction has ended (and with it SQLite's write lock): effects, then the new state.
    if expired:
        ctx.notifier.publish(participant_id)
        conflict = Conflict("you were away longer than this study allows, so it has ended for you")
    if conflict is not None:
        if conflict.state is None:
            conflict.state = _reload_state(ctx, token)
        raise conflict
    if done is not None:
        ctx.notifier.publish(participant_id)
        if done.wake_runtime:
            ctx.runtime.wake()
        for effect in done.effects:
            try:
                effect()
            except Exception:  # noqa: BLE001 - the action is stored; an effect only shows or tidies it
                log.exception("an effect of the %s action of participant %s failed", action, participant_id)
    return participant_state(ctx, token, replayed=replayed)


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
