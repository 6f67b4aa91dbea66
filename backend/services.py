"""One function per user action: load state from the database, call the learning core, move the robot, commit once.

Participants go through consent -> instructions -> one teaching session per task (practice,
demonstrations, queries, tests; core.session enforces their order) -> questionnaire -> done. Every
action appends to the participant's event log in the same transaction that changes their state, so
an acknowledged action is never lost. A client-supplied idempotency key makes retries harmless.
"""

from __future__ import annotations

import hashlib
import json
import logging
import secrets
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from functools import lru_cache
from typing import Any

from .config import Settings
from .core import session as core
from .core.domain import DINNER_OBJECTS, get_domain
from .core.priors import NAMED_PRIORS
from .core.puns import CRITERIA
from .db import repository as repo
from .db.engine import Database
from .db.tables import EventRow, ParticipantRow, StudyRow, TaskSessionRow, utcnow
from .errors import Conflict, InvalidInput, NotAuthenticated, NotFound
from .robot import Robot, ViewingRobot, make_robot
from .sim.recordings import RecordingId

log = logging.getLogger(__name__)

TASK_FORMULAS = {
    "task1": "F(dinner_plate) & F(small_plate) & F(bowl) & F(knife) & F(fork) & (!small_plate U dinner_plate)"
    " & (!bowl U small_plate) & (!bowl U dinner_plate)",
    "task2": "G(!small_plate) & F(dinner_plate) & F(bowl) & (!bowl U dinner_plate)",
}
TASK_NAMES = {"task1": "Task 1: set the table for dinner", "task2": "Task 2: a light meal"}
TASK_INSTRUCTIONS = {
    "task1": "Place all five objects. The dinner plate comes first of the three dishes, then the small plate, "
    "then the bowl; the knife and fork may be placed at any time.",
    "task2": "Place the dinner plate and then the bowl; never place the small plate. The knife and fork are "
    "optional. Finish the demonstration when you are done.",
}
TASK_KEYS = ("task1", "task2", "custom", "none")
ASSIGNMENTS = ("random", "balanced")
STUDY_STATUSES = ("draft", "open", "closed")
ITEM_KINDS = {"likert5": (1, 5), "rating10": (1, 10), "text": None}
STAGES = ("consent", "instructions", "task", "questionnaire", "done", "withdrawn")
DEMO_STUDY_ID = "demo"
DEFAULT_CONSENT = (
    "You will teach a simulated robot to set a table by showing it and by judging its attempts. "
    "Your actions and answers are recorded without your name. You may stop at any time."
)
DEMO_QUESTIONNAIRE = [
    {"id": "learned", "text": "The robot learned the task I was teaching.", "kind": "likert5", "required": True},
    {"id": "queries_useful", "text": "The robot's questions helped it learn.", "kind": "likert5", "required": True},
    {"id": "easy", "text": "Teaching the robot was easy.", "kind": "likert5", "required": True},
    {"id": "trust", "text": "I would trust the robot to do this task on its own.", "kind": "likert5", "required": True},
    {"id": "again", "text": "I would like to teach a robot this way again.", "kind": "likert5", "required": True},
    {"id": "overall", "text": "Overall, how well did the robot learn? (1 = not at all, 10 = perfectly)",
     "kind": "rating10", "required": True},
    {"id": "comments", "text": "Anything else you want to tell us?", "kind": "text", "required": False},
]


@lru_cache(maxsize=1)
def app_version() -> str:
    """The installed tableteach version, written into every event."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tableteach")
    except PackageNotFoundError:
        return "unknown"


TAB_LEASE_SECONDS = 15.0


class TabLeases:
    """Which browser tab holds each participant's page; in the process, like the robot's executions."""

    def __init__(self, seconds: float = TAB_LEASE_SECONDS) -> None:
        self.seconds = seconds
        self._holders: dict[int, tuple[str, float]] = {}
        self._lock = threading.Lock()

    def claim(self, participant_id: int, tab_id: str, *, takeover: bool = False) -> bool:
        """Hold or renew the lease; False while another tab's lease is still fresh (unless takeover)."""
        now = time.monotonic()
        with self._lock:
            holder = self._holders.get(participant_id)
            if holder is not None and holder[0] != tab_id and holder[1] > now and not takeover:
                return False
            self._holders[participant_id] = (tab_id, now + self.seconds)
            return True

    def release(self, participant_id: int, tab_id: str) -> None:
        """Give the lease up (the tab is closing or reloading) if this tab holds it."""
        with self._lock:
            if self._holders.get(participant_id, ("",))[0] == tab_id:
                del self._holders[participant_id]


@dataclass
class Context:
    """What every action needs: the database, the robot and the settings (plus the page's tab leases)."""

    db: Database
    robot: Robot
    settings: Settings
    tabs: TabLeases = field(default_factory=TabLeases)

    @staticmethod
    def from_settings(settings: Settings) -> "Context":
        """Open the database and build the robot the settings name."""
        robot = make_robot(settings.robot, seconds_per_object=settings.robot_seconds_per_object,
                           speed=settings.robot_speed, data_dir=settings.data_dir,
                           idle_seconds=settings.viewer_idle_minutes * 60)
        return Context(Database(settings.database_url), robot, settings)


def _aware(value: datetime | None) -> datetime | None:
    """SQLite returns naive datetimes; every stored time is UTC."""
    if value is None or value.tzinfo is not None:
        return value
    return value.replace(tzinfo=timezone.utc)


def _iso(value: datetime | None) -> str | None:
    value = _aware(value)
    return None if value is None else value.isoformat()


# ====================================================================== studies


def _check_tasks(tasks: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Fill in the named tasks' formulas and check custom ones against the dinner clause templates."""
    if not tasks:
        raise InvalidInput("a study needs at least one task; expected e.g. [{'key': 'task1'}]")
    space = get_domain("dinner").clause_space
    out = []
    for i, task in enumerate(tasks):
        key = task.get("key")
        if key not in TASK_KEYS:
            raise InvalidInput(f"tasks[{i}].key is {key!r}; expected one of {', '.join(TASK_KEYS)}")
        formula = task.get("ground_truth") or None
        if key in TASK_FORMULAS:
            if formula:
                raise InvalidInput(f"tasks[{i}] is {key}, whose ground truth is fixed; leave ground_truth empty")
            formula = TASK_FORMULAS[key]
        elif key == "custom":
            if not formula:
                raise InvalidInput(f"tasks[{i}] is custom and needs a ground_truth formula over {', '.join(DINNER_OBJECTS)}")
            try:
                formula = space.text_of(space.mask_of_formula(formula))
            except ValueError as exc:
                raise InvalidInput(f"tasks[{i}].ground_truth: {exc}") from exc
        elif formula:
            raise InvalidInput(f"tasks[{i}] has key 'none' (ground truth unknown); use 'custom' to give a formula")
        mask = None if formula is None else space.mask_of_formula(formula)
        out.append({
            "key": key,
            "ground_truth": formula,
            "name": task.get("name") or TASK_NAMES.get(key, f"Task {i + 1}"),
            "instructions": task.get("instructions")
            or TASK_INSTRUCTIONS.get(key)
            or ("" if mask is None else space.describe(mask).capitalize() + "."),
        })
    return out


def _check_questionnaire(items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Items need a unique id, a text and a kind of likert5, rating10 or text."""
    seen: set[str] = set()
    out = []
    for i, item in enumerate(items):
        item_id, kind = item.get("id"), item.get("kind")
        if not isinstance(item_id, str) or not item_id or item_id in seen:
            raise InvalidInput(f"questionnaire[{i}].id must be a non-empty id not used before, got {item_id!r}")
        if kind not in ITEM_KINDS:
            raise InvalidInput(f"questionnaire[{i}].kind is {kind!r}; expected one of {', '.join(ITEM_KINDS)}")
        seen.add(item_id)
        out.append({"id": item_id, "text": str(item.get("text", "")), "kind": kind, "required": bool(item.get("required", True))})
    return out


def _study_values(spec: dict[str, Any]) -> dict[str, Any]:
    """Validated column values of a new study."""
    conditions = list(spec.get("conditions") or [])
    if not conditions or len(set(conditions)) != len(conditions) or any(c not in core.PROTOCOLS for c in conditions):
        raise InvalidInput(f"conditions must be distinct protocols from {', '.join(core.PROTOCOLS)}, got {conditions!r}")
    assignment = spec.get("assignment", "balanced")
    if assignment not in ASSIGNMENTS:
        raise InvalidInput(f"assignment is {assignment!r}; expected one of {', '.join(ASSIGNMENTS)}")
    if spec.get("prior", core.DEFAULT_PRIOR) not in NAMED_PRIORS:
        raise InvalidInput(f"prior is {spec.get('prior')!r}; expected one of {', '.join(NAMED_PRIORS)}")
    if spec.get("criterion", "min-regret") not in CRITERIA:
        raise InvalidInput(f"criterion is {spec.get('criterion')!r}; expected one of {', '.join(CRITERIA)}")
    counts = {name: spec.get(name, default) for name, default in
              (("n_practice", 1), ("n_demonstrations", 2), ("n_queries", 3), ("n_tests", 3))}
    for name, value in counts.items():
        if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 20:
            raise InvalidInput(f"{name} must be a whole number from 0 to 20, got {value!r}")
    url = spec.get("completion_url")
    if url is not None and not str(url).startswith(("https://", "http://")):
        raise InvalidInput(f"completion_url must start with https:// or http://, got {url!r}")
    return {
        "name": spec.get("name") or "Untitled study",
        "tasks": _check_tasks(list(spec.get("tasks") or [])),
        "conditions": conditions,
        "assignment": assignment,
        **counts,
        "prior": spec.get("prior", core.DEFAULT_PRIOR),
        "criterion": spec.get("criterion", "min-regret"),
        "questionnaire": _check_questionnaire(list(spec.get("questionnaire") or [])),
        "consent_text": spec.get("consent_text") or DEFAULT_CONSENT,
        "consent_version": spec.get("consent_version") or "1",
        "completion_url": url,
        "pilot": bool(spec.get("pilot", False)),
        "status": "draft",
    }


def study_view(study: StudyRow) -> dict[str, Any]:
    """A study as the experimenter API shows it."""
    return {
        "id": study.id, "name": study.name, "status": study.status, "pilot": study.pilot,
        "tasks": study.tasks, "conditions": study.conditions, "assignment": study.assignment,
        "n_practice": study.n_practice, "n_demonstrations": study.n_demonstrations,
        "n_queries": study.n_queries, "n_tests": study.n_tests, "prior": study.prior,
        "criterion": study.criterion, "questionnaire": study.questionnaire,
        "consent_text": study.consent_text, "consent_version": study.consent_version,
        "completion_url": study.completion_url,
        "created_at": _iso(study.created_at), "updated_at": _iso(study.updated_at),
    }


def create_study(ctx: Context, spec: dict[str, Any], *, study_id: str | None = None) -> dict[str, Any]:
    """Create a study in draft status."""
    values = _study_values(spec)
    with ctx.db.write() as s:
        sid = study_id or "s-" + secrets.token_urlsafe(6).replace("_", "x").replace("-", "x").lower()
        if repo.get_study(s, study_id=sid) is not None:
            raise Conflict(f"a study with id {sid!r} already exists")
        study = repo.add_study(s, values={"id": sid, **values})
        _commit(s)
        return study_view(study)


def _set_study_status(ctx: Context, study_id: str, status: str) -> dict[str, Any]:
    allowed = {"open": ("draft", "closed", "open"), "closed": ("open", "draft", "closed")}[status]
    with ctx.db.write() as s:
        study = _study(s, study_id)
        if study.status not in allowed:
            raise Conflict(f"study {study_id!r} is {study.status}; it cannot become {status}")
        study.status = status
        _commit(s)
        return study_view(study)


def open_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """Let participants join."""
    return _set_study_status(ctx, study_id, "open")


def close_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """Stop new participants from joining (those under way may finish)."""
    return _set_study_status(ctx, study_id, "closed")


def list_studies(ctx: Context) -> list[dict[str, Any]]:
    """Every study."""
    with ctx.db.read() as s:
        return [study_view(st) for st in repo.list_studies(s)]


def get_study(ctx: Context, study_id: str) -> dict[str, Any]:
    """One study."""
    with ctx.db.read() as s:
        return study_view(_study(s, study_id))


def seed_demo_study(ctx: Context) -> dict[str, Any]:
    """The demo study (Task 1 then Task 2, Active protocol), created once and left open."""
    with ctx.db.read() as s:
        existing = repo.get_study(s, study_id=DEMO_STUDY_ID)
        if existing is not None:
            return study_view(existing)
    spec = {
        "name": "Demo: set the dinner table (Task 1 and Task 2, Active)",
        "tasks": [{"key": "task1"}, {"key": "task2"}],
        "conditions": ["active"],
        "questionnaire": DEMO_QUESTIONNAIRE,
        "pilot": True,
    }
    try:
        create_study(ctx, spec, study_id=DEMO_STUDY_ID)
    except Conflict:
        pass  # another process seeded it at the same moment
    return open_study(ctx, DEMO_STUDY_ID)


def _study(s: Any, study_id: str) -> StudyRow:
    study = repo.get_study(s, study_id=study_id)
    if study is None:
        raise NotFound(f"no study with id {study_id!r}")
    return study


def _commit(s: Any) -> None:
    try:
        repo.commit(s)
    except repo.WriteConflict as exc:
        raise Conflict(f"a concurrent request changed the same data first; reload and retry ({exc})") from exc


# ====================================================================== joining


def _choose_condition(s: Any, study: StudyRow, settings: Settings) -> str:
    """Random, or balanced over participants who finished or were active recently (ties at random)."""
    rng = secrets.SystemRandom()
    if study.assignment == "random" or len(study.conditions) == 1:
        return rng.choice(study.conditions)
    since = utcnow() - timedelta(minutes=settings.active_minutes)
    counts = repo.count_by_condition(s, study_id=study.id, active_since=since)
    fewest = min(counts.get(c, 0) for c in study.conditions)
    return rng.choice([c for c in study.conditions if counts.get(c, 0) == fewest])


def join_study(
    ctx: Context, study_id: str, *, prolific_pid: str | None = None, external_study_id: str | None = None,
    external_session_id: str | None = None,
) -> tuple[dict[str, Any], bool]:
    """A new participant (or the one who joined before with this external id) and whether it is new."""
    with ctx.db.write() as s:
        study = repo.get_study(s, study_id=study_id, for_update=True)
        if study is None:
            raise NotFound(f"no study with id {study_id!r}")
        if prolific_pid:
            existing = repo.find_participant_by_external_id(s, study_id=study_id, prolific_pid=prolific_pid)
            if existing is not None:
                return _state(s, existing, study), False
        if study.status != "open":
            raise Conflict(f"study {study_id!r} is {study.status}; participants can join only while it is open")
        participant = repo.add_participant(s, values={
            "token": secrets.token_urlsafe(24),
            "study_id": study.id,
            "prolific_pid": prolific_pid or None,
            "external_study_id": external_study_id or None,
            "external_session_id": external_session_id or None,
            "condition": _choose_condition(s, study, ctx.settings),
            "seed": secrets.randbelow(2**31 - 1000),
            "pilot": study.pilot,
            "stage": "consent",
            "task_index": 0,
            "n_events": 0,
        })
        repo.append_event(s, participant=participant, kind="joined", app_version=app_version(), payload={
            "condition": participant.condition, "prolific_pid": prolific_pid, "external_study_id": external_study_id,
            "external_session_id": external_session_id,
        })
        _commit(s)
        return _state(s, participant, study), True


# ====================================================================== participant state


def _robot_key(participant: ParticipantRow, task_index: int) -> str:
    return f"{participant.id}/{task_index}"


def _save_recording(ctx: Context, participant: ParticipantRow, task_index: int, kind: str, index: int) -> None:
    """Ask the robot to keep this step's motion; a failure is logged, never shown to the participant."""
    try:
        ctx.robot.save_recording(_robot_key(participant, task_index),
                                 RecordingId(participant.id, task_index, kind, index).name)
    except Exception:
        log.exception("could not save the recording of participant %s task %s %s %s", participant.id, task_index,
                      kind, index)


def _session_config(study: StudyRow, participant: ParticipantRow, task_index: int) -> core.SessionConfig:
    return core.SessionConfig(
        task="dinner", prior=study.prior, protocol=participant.condition,
        # The practice trial is there to learn the interface, so only the first task has one.
        n_practice=study.n_practice if task_index == 0 else 0,
        n_demonstrations=study.n_demonstrations, n_queries=study.n_queries, n_tests=study.n_tests,
        criterion=study.criterion, seed=(participant.seed + task_index) % (2**31),
    )


def _current_task(s: Any, participant: ParticipantRow) -> TaskSessionRow | None:
    if participant.stage != "task":
        return None
    return repo.get_task_session(s, participant_id=participant.id, task_index=participant.task_index)


def _sync_execution(ctx: Context, s: Any, participant: ParticipantRow, ts: TaskSessionRow) -> bool:
    """Ask the robot how a running execution is going; True if it has just finished (state changed)."""
    execution = ts.execution
    if execution is None or execution["status"] != "running":
        return False
    key = _robot_key(participant, ts.task_index)
    progress = ctx.robot.progress(key)
    if progress is None or list(progress.events) != execution["events"]:
        # The robot forgot it (server restart): it starts the same execution again.
        log.info("robot lost execution %s; restarting it", key)
        ctx.robot.execute(key, execution["events"])
        progress = ctx.robot.progress(key)
    if progress is None or not progress.finished:
        return False
    trace = [sorted(labels) for labels in progress.trace]
    ts.execution = {**execution, "status": "finished", "trace": trace, "finished_at": utcnow().isoformat()}
    _save_recording(ctx, participant, ts.task_index, execution["kind"], execution["index"])
    repo.append_event(
        s, participant=participant, kind="execution_finished", app_version=app_version(),
        task_index=ts.task_index, step_kind=execution["kind"], step_index=execution["index"],
        payload={"events": execution["events"], "trace": trace},
    )
    return True


@lru_cache(maxsize=2048)
def _step_of(state_json: str) -> tuple[core.SessionState, core.Step]:
    """The core state and its next step (cached: planning a query costs milliseconds, states repeat)."""
    state = core.SessionState.from_json(state_json)
    return state, core.next_step(state)


def _state(s: Any, participant: ParticipantRow, study: StudyRow, *, replayed: bool = False) -> dict[str, Any]:
    """What a participant (or scripted teacher) sees: stage, current step, robot and questionnaire."""
    out: dict[str, Any] = {
        "participant_id": participant.id,
        "token": participant.token,
        "study_id": study.id,
        "stage": participant.stage,
        "n_events": participant.n_events,
        "objects": list(DINNER_OBJECTS),
        "consent": {"text": study.consent_text, "version": study.consent_version,
                    "given_at": _iso(participant.consent_at)},
        "task": None, "step": None, "demonstration": None, "execution": None,
        "questionnaire": None, "completion": None, "replayed": replayed,
    }
    if participant.stage == "task":
        ts = _current_task(s, participant)
        task = study.tasks[participant.task_index]
        out["task"] = {"index": participant.task_index, "total": len(study.tasks), "name": task["name"],
                       "instructions": task["instructions"], "key": task["key"]}
        if ts is not None:
            _, step = _step_of(ts.state_json)
            out["step"] = {"kind": step.kind, "index": step.index, "total": step.total}
            if step.kind in ("practice", "demonstration"):
                out["demonstration"] = {"placed": list(ts.demo_placed),
                                        "labels": ts.demo_trace[-1] if ts.demo_trace else [],
                                        "trace": list(ts.demo_trace)}
            elif step.kind in ("query", "test"):
                ex = ts.execution
                if ex is not None and (ex["kind"], ex["index"]) == (step.kind, step.index):
                    out["execution"] = {"kind": ex["kind"], "index": ex["index"], "status": ex["status"],
                                        "events": ex["events"], "trace": ex.get("trace")}
                else:
                    out["execution"] = {"kind": step.kind, "index": step.index, "status": "not_started",
                                        "events": None, "trace": None}
    elif participant.stage == "questionnaire":
        out["questionnaire"] = study.questionnaire
    elif participant.stage == "done":
        out["completion"] = {"code": participant.completion_code,
                             "redirect_url": _completion_url(study, participant.completion_code),
                             "learned": _learned(s, participant)}
    return out


def _learned(s: Any, participant: ParticipantRow) -> list[dict[str, Any]]:
    """The debriefing: what the robot believes each task is, once the participant has finished."""
    space = get_domain("dinner").clause_space
    out = []
    for ts in repo.task_sessions_of(s, participant_id=participant.id):
        b = core.belief(core.SessionState.from_json(ts.state_json))
        out.append({"task_index": ts.task_index, "map_formula": space.text_of(b.map_mask),
                    "map_description": space.describe(b.map_mask)})
    return out


def _completion_url(study: StudyRow, code: str | None) -> str | None:
    if not study.completion_url:
        return None
    return study.completion_url.replace("{code}", code or "")


def participant_state(ctx: Context, token: str) -> dict[str, Any]:
    """The participant's state; a robot execution that has finished meanwhile is recorded first."""
    with ctx.db.read() as s:
        participant, study = _participant(s, token)
        ts = _current_task(s, participant)
        needs_write = ts is not None and ts.execution is not None and ts.execution["status"] == "running"
        if not needs_write:
            return _state(s, participant, study)
    with ctx.db.write() as s:
        participant, study = _participant(s, token)
        ts = _current_task(s, participant)
        if ts is not None and _sync_execution(ctx, s, participant, ts):
            _commit(s)
        return _state(s, participant, study)


def _participant(s: Any, token: str) -> tuple[ParticipantRow, StudyRow]:
    participant = repo.get_participant_by_token(s, token=token) if token else None
    if participant is None:
        raise NotAuthenticated("unknown participant token; use the link you were given (Authorization: Bearer <token>)")
    study = repo.get_study(s, study_id=participant.study_id)
    assert study is not None  # foreign key
    return participant, study


# ====================================================================== participant actions


@dataclass
class Expect:
    """Where the client believes the session is; a mismatch (second tab, stale page) is a 409."""

    task_index: int | None = None
    step_kind: str | None = None
    step_index: int | None = None


@dataclass
class _Action:
    """One participant request being carried out: its log writes carry the idempotency key."""

    ctx: Context
    s: Any
    participant: ParticipantRow
    study: StudyRow
    key: str | None
    digest: str | None
    events: list[EventRow] = field(default_factory=list)

    def log(self, kind: str, payload: dict[str, Any], *, task_index: int | None = None,
            step_kind: str | None = None, step_index: int | None = None) -> None:
        """Append an event; the first one of the request stores the client's key."""
        first = not self.events
        self.events.append(repo.append_event(
            self.s, participant=self.participant, kind=kind, payload=payload, app_version=app_version(),
            task_index=task_index, step_kind=step_kind, step_index=step_index,
            client_event_id=self.key if first else None, request_digest=self.digest if first else None,
        ))


def _digest(action: str, body: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps([action, body], sort_keys=True, default=str).encode()).hexdigest()


def _act(ctx: Context, token: str, action: str, body: dict[str, Any], key: str | None,
         run: Callable[[_Action], None]) -> dict[str, Any]:
    """Run one participant action in a write transaction: replay check, change, log, commit, new state."""
    digest = _digest(action, body)
    with ctx.db.write() as s:
        participant, study = _participant(s, token)
        if key is not None:
            previous = repo.find_event_by_client_id(s, participant_id=participant.id, client_event_id=key)
            if previous is not None:
                if previous.request_digest == digest:
                    return _state(s, participant, study, replayed=True)
                raise Conflict(f"Idempotency-Key {key!r} was already used for a different request "
                               f"({previous.kind}); use a new key for a new action",
                               state=_state(s, participant, study))
        try:
            run(_Action(ctx, s, participant, study, key, digest))
            repo.commit(s)
            return _state(s, participant, study)
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


def _require_stage(a: _Action, stage: str) -> None:
    if a.participant.stage != stage:
        raise Conflict(f"this action belongs to the {stage} stage, but the participant is at the "
                       f"{a.participant.stage} stage")


def give_consent(ctx: Context, token: str, *, agree: bool, consent_version: str, key: str | None = None) -> dict[str, Any]:
    """Record consent (or its refusal, which withdraws the participant)."""
    def run(a: _Action) -> None:
        _require_stage(a, "consent")
        if consent_version != a.study.consent_version:
            raise Conflict(f"consent text version {consent_version!r} is not the current one "
                           f"({a.study.consent_version!r}); reload the page and read it again")
        now = utcnow()
        a.log("consent", {"agree": agree, "consent_version": consent_version, "at": now.isoformat()})
        if agree:
            a.participant.consent_at = now
            a.participant.consent_version = consent_version
            a.participant.stage = "instructions"
        else:
            a.participant.stage = "withdrawn"
            a.participant.finished_at = now

    return _act(ctx, token, "consent", {"agree": agree, "version": consent_version}, key, run)


def finish_instructions(ctx: Context, token: str, *, key: str | None = None) -> dict[str, Any]:
    """The participant has read the instructions: the first task begins."""
    def run(a: _Action) -> None:
        _require_stage(a, "instructions")
        a.log("instructions_read", {})
        _begin_task(a, 0)

    return _act(ctx, token, "instructions", {}, key, run)


def _begin_task(a: _Action, task_index: int) -> None:
    a.participant.stage = "task"
    a.participant.task_index = task_index
    config = _session_config(a.study, a.participant, task_index)
    repo.add_task_session(a.s, participant_id=a.participant.id, task_index=task_index,
                          state_json=core.start(config).to_json())
    task = a.study.tasks[task_index]
    a.log("task_started", {"task": task["key"], "ground_truth": task["ground_truth"], "protocol": config.protocol,
                           "seed": config.seed}, task_index=task_index)


def _teaching(a: _Action, expect: Expect, kinds: tuple[str, ...]) -> tuple[TaskSessionRow, core.SessionState, core.Step]:
    """The current task session and step; Conflict unless the step is one of kinds and matches expect."""
    _require_stage(a, "task")
    ts = repo.get_task_session(a.s, participant_id=a.participant.id, task_index=a.participant.task_index)
    assert ts is not None
    state, step = _step_of(ts.state_json)
    here = f"{step.kind} {step.index + 1} of {step.total} in task {a.participant.task_index + 1}"
    if expect.task_index is not None and expect.task_index != a.participant.task_index:
        raise Conflict(f"this request is for task {expect.task_index + 1}, but the session is at {here}")
    if (expect.step_kind is not None and expect.step_kind != step.kind) or (
        expect.step_index is not None and expect.step_index != step.index
    ):
        want = f"{expect.step_kind or step.kind} {(expect.step_index if expect.step_index is not None else step.index) + 1}"
        raise Conflict(f"this request is for {want}, but the session is at {here}")
    if step.kind not in kinds:
        raise Conflict(f"the session is at {here}; this action needs a {' or '.join(kinds)} step")
    return ts, state, step


def _sync_demonstration(a: _Action, ts: TaskSessionRow) -> None:
    """Make the robot's table match the stored placements (it forgets them on a restart)."""
    key = _robot_key(a.participant, ts.task_index)
    if not ts.demo_trace:
        initial = a.ctx.robot.reset(key)
        ts.demo_trace = [sorted(initial)]
    elif a.ctx.robot.placed(key) != tuple(ts.demo_placed):
        a.ctx.robot.reset(key)
        for obj in ts.demo_placed:
            a.ctx.robot.place(key, obj)


def place_object(ctx: Context, token: str, *, obj: str, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """During a practice trial or demonstration, the participant places one object on the table."""
    def run(a: _Action) -> None:
        ts, _state_, step = _teaching(a, expect, ("practice", "demonstration"))
        if obj not in DINNER_OBJECTS:
            raise InvalidInput(f"unknown object {obj!r}; expected one of {', '.join(DINNER_OBJECTS)}")
        if obj in ts.demo_placed:
            raise Conflict(f"the {obj} is already on the table; a placed object cannot be placed again")
        _sync_demonstration(a, ts)
        try:
            labels = a.ctx.robot.place(_robot_key(a.participant, ts.task_index), obj)
        except ValueError as exc:
            raise Conflict(f"the robot could not place the {obj}: {exc}") from exc
        ts.demo_placed = [*ts.demo_placed, obj]
        ts.demo_trace = [*ts.demo_trace, sorted(labels)]
        a.log("place", {"object": obj, "labels": sorted(labels), "placed": list(ts.demo_placed)},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)

    return _act(ctx, token, "place", {"object": obj, **expect.__dict__}, key, run)


def finish_demonstration(ctx: Context, token: str, *, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """End the practice trial or demonstration (stopping early is allowed: Task 2 needs it)."""
    def run(a: _Action) -> None:
        ts, state, step = _teaching(a, expect, ("practice", "demonstration"))
        _sync_demonstration(a, ts)
        trace = [list(labels) for labels in ts.demo_trace]
        new_state = core.observe(state, step.kind, trace)
        a.log("demonstration", {"placed": list(ts.demo_placed), "trace": trace},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        if ts.demo_placed:
            _save_recording(a.ctx, a.participant, ts.task_index, step.kind, step.index)
        ts.demo_placed, ts.demo_trace = [], []
        a.ctx.robot.release(_robot_key(a.participant, ts.task_index))
        _advance(a, ts, new_state)

    return _act(ctx, token, "finish", dict(expect.__dict__), key, run)


def start_execution(ctx: Context, token: str, *, expect: Expect, key: str | None = None) -> dict[str, Any]:
    """The robot carries out the current query or test execution (starting it twice is harmless)."""
    def run(a: _Action) -> None:
        ts, state, step = _teaching(a, expect, ("query", "test"))
        ex = ts.execution
        if ex is not None and (ex["kind"], ex["index"]) == (step.kind, step.index):
            _sync_execution(a.ctx, a.s, a.participant, ts)
            return  # a second click on "run": the same execution is already under way or done
        assert step.robot_execution is not None
        events = list(step.robot_execution.events)
        a.ctx.robot.execute(_robot_key(a.participant, ts.task_index), events)
        ts.execution = {"kind": step.kind, "index": step.index, "events": events, "status": "running",
                        "trace": None, "p_acceptable": step.p_acceptable, "started_at": utcnow().isoformat()}
        a.log("execution_started", {"events": events, "p_acceptable": step.p_acceptable},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        _sync_execution(a.ctx, a.s, a.participant, ts)

    return _act(ctx, token, "execute", dict(expect.__dict__), key, run)


def assess_execution(ctx: Context, token: str, *, acceptable: bool | None, expect: Expect,
                     key: str | None = None) -> dict[str, Any]:
    """The participant's verdict on the robot's finished execution (required for queries)."""
    def run(a: _Action) -> None:
        ts, state, step = _teaching(a, expect, ("query", "test"))
        ex = ts.execution
        if ex is None or (ex["kind"], ex["index"]) != (step.kind, step.index):
            raise Conflict(f"the robot has not started {step.kind} {step.index + 1} yet; start its execution first")
        _sync_execution(a.ctx, a.s, a.participant, ts)
        ex = ts.execution
        if ex["status"] != "finished":
            raise Conflict(f"the robot is still carrying out {step.kind} {step.index + 1}; "
                           "assess it once the execution has finished")
        if step.kind == "query" and acceptable is None:
            raise InvalidInput("a query needs an assessment: acceptable must be true or false")
        new_state = core.observe(state, step.kind, ex["trace"], acceptable)
        a.log("assessment", {"acceptable": acceptable, "events": ex["events"], "trace": ex["trace"],
                             "p_acceptable": ex.get("p_acceptable")},
              task_index=ts.task_index, step_kind=step.kind, step_index=step.index)
        ts.execution = None
        a.ctx.robot.release(_robot_key(a.participant, ts.task_index))
        _advance(a, ts, new_state)

    return _act(ctx, token, "assess", {"acceptable": acceptable, **expect.__dict__}, key, run)


def _advance(a: _Action, ts: TaskSessionRow, new_state: core.SessionState) -> None:
    """Store the core's new state; after the last step of a task, go to the next task or the questionnaire."""
    ts.state_json = new_state.to_json()
    if new_state.phase != "done":
        return
    a.log("task_finished", {}, task_index=ts.task_index)
    a.ctx.robot.close(_robot_key(a.participant, ts.task_index))  # the next task has its own table (and view)
    if ts.task_index + 1 < len(a.study.tasks):
        _begin_task(a, ts.task_index + 1)
    elif a.study.questionnaire:
        a.participant.stage = "questionnaire"
    else:
        _complete(a)


def _complete(a: _Action) -> None:
    a.participant.stage = "done"
    a.participant.finished_at = utcnow()
    a.participant.completion_code = secrets.token_hex(4).upper()
    a.log("completed", {"completion_code": a.participant.completion_code})


def _check_answer(item: dict[str, Any], value: Any) -> Any:
    bounds = ITEM_KINDS[item["kind"]]
    if bounds is None:
        if not isinstance(value, str) or len(value) > 5000:
            raise InvalidInput(f"answer to {item['id']!r} must be text of at most 5000 characters")
        return value
    low, high = bounds
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise InvalidInput(f"answer to {item['id']!r} must be a whole number from {low} to {high}, got {value!r}")
    return value


def answer_questionnaire(ctx: Context, token: str, *, answers: dict[str, Any], key: str | None = None) -> dict[str, Any]:
    """Store the questionnaire's answers; the participant is then done and gets a completion code."""
    def run(a: _Action) -> None:
        _require_stage(a, "questionnaire")
        items = {item["id"]: item for item in a.study.questionnaire}
        unknown = sorted(set(answers) - set(items))
        if unknown:
            raise InvalidInput(f"unknown questionnaire item(s) {', '.join(map(repr, unknown))}; "
                               f"expected some of {', '.join(items)}")
        missing = [i for i, item in items.items() if item["required"] and answers.get(i) in (None, "")]
        if missing:
            raise InvalidInput(f"required questionnaire item(s) not answered: {', '.join(missing)}")
        clean = {i: _check_answer(items[i], v) for i, v in answers.items() if v is not None}
        a.log("questionnaire", {"answers": clean})
        _complete(a)

    return _act(ctx, token, "questionnaire", {"answers": answers}, key, run)


# ====================================================================== participant page: 3D view and tab


def open_viewer(ctx: Context, token: str) -> int | None:
    """The local port of the participant's 3D view for the current step, or None (no task, or a robot without view).

    The view is started on first use and shows the stored state of the step (the robot forgets its
    tables on a restart); during a practice trial or demonstration a click on a waiting object is a
    placement through place_object, the same code path as POST /me/placements.
    """
    robot = ctx.robot
    if not isinstance(robot, ViewingRobot):
        with ctx.db.read() as s:
            _participant(s, token)  # an unknown token is refused whatever the robot
        return None
    # A write transaction (never committed) so that no placement is stored while the table is synced.
    with ctx.db.write() as s:
        participant, _study = _participant(s, token)
        ts = _current_task(s, participant)
        if ts is None:
            return None
        _, step = _step_of(ts.state_json)
        key = _robot_key(participant, ts.task_index)
        on_click: Callable[[str], None] | None = None
        if step.kind in ("practice", "demonstration"):
            if ts.demo_trace and robot.placed(key) != tuple(ts.demo_placed):
                robot.reset(key)
                for obj in ts.demo_placed:
                    robot.place(key, obj)
            expect = Expect(ts.task_index, step.kind, step.index)

            def on_click(obj: str) -> None:
                _place_clicked(ctx, token, obj, expect)
        else:
            ex = ts.execution
            if (ex is not None and ex["status"] == "finished" and (ex["kind"], ex["index"]) == (step.kind, step.index)
                    and robot.progress(key) is None):
                robot.execute(key, ex["events"])  # show the finished execution again after a restart
        return robot.open_view(key, on_click)


def _place_clicked(ctx: Context, token: str, obj: str, expect: Expect) -> None:
    """A click in the 3D view; one that came too late for its step is dropped."""
    try:
        place_object(ctx, token, obj=obj, expect=expect)
    except (Conflict, InvalidInput) as exc:
        log.info("click on %s not placed: %s", obj, exc.message)


def robot_activity(ctx: Context, token: str) -> dict[str, Any]:
    """What the participant's robot is doing now: moving, a caption, and how many views are connected."""
    with ctx.db.read() as s:
        participant, _study = _participant(s, token)
        ts = _current_task(s, participant)
        key = None if ts is None else _robot_key(participant, ts.task_index)
    robot = ctx.robot
    viewing = isinstance(robot, ViewingRobot)
    activity = robot.activity(key) if viewing and key is not None else None
    return {"view": viewing, "moving": bool(activity and activity.moving),
            "caption": activity.caption if activity else "", "watchers": activity.watchers if activity else 0}


def claim_tab(ctx: Context, token: str, tab_id: str, *, takeover: bool = False) -> dict[str, Any]:
    """Hold (or renew) the one-tab lease of the participant's page; held is False while another tab holds it."""
    with ctx.db.read() as s:
        participant, _study = _participant(s, token)
        pid = participant.id
    held = ctx.tabs.claim(pid, tab_id, takeover=takeover)
    return {"held": held, "lease_seconds": ctx.tabs.seconds}


def release_tab(ctx: Context, token: str, tab_id: str) -> None:
    """The tab is going away (reload or close): let the next one take over at once."""
    with ctx.db.read() as s:
        participant, _study = _participant(s, token)
        pid = participant.id
    ctx.tabs.release(pid, tab_id)


# ====================================================================== experimenter views


def _live_status(participant: ParticipantRow, settings: Settings) -> str:
    if participant.stage in ("done", "withdrawn"):
        return participant.stage
    last = _aware(participant.last_activity_at) or utcnow()
    return "active" if utcnow() - last <= timedelta(minutes=settings.active_minutes) else "idle"


def list_participants(ctx: Context, study_id: str) -> list[dict[str, Any]]:
    """A study's participants with their stage, live status and last activity."""
    with ctx.db.read() as s:
        _study(s, study_id)
        out = []
        for p in repo.list_participants(s, study_id=study_id):
            step = None
            ts = _current_task(s, p)
            if ts is not None:
                nxt = core.SessionState.from_json(ts.state_json).phase
                step = nxt
            out.append({
                "participant_id": p.id, "condition": p.condition, "stage": p.stage, "task_index": p.task_index,
                "phase": step, "status": _live_status(p, ctx.settings), "pilot": p.pilot,
                "prolific_pid": p.prolific_pid, "created_at": _iso(p.created_at),
                "last_activity_at": _iso(p.last_activity_at), "finished_at": _iso(p.finished_at),
                "n_events": p.n_events, "completion_code": p.completion_code,
            })
        return out


def _truth_mask(task: dict[str, Any]) -> int | None:
    formula = task.get("ground_truth")
    return None if formula is None else get_domain("dinner").clause_space.mask_of_formula(formula)


def belief_summary(ctx: Context, study_id: str, participant_id: int, *, top: int = 5) -> dict[str, Any]:
    """Per task: the learner's top formulas in plain English, entropy and similarity to the ground truth."""
    space = get_domain("dinner").clause_space
    with ctx.db.read() as s:
        study = _study(s, study_id)
        participant = repo.get_participant(s, study_id=study_id, participant_id=participant_id)
        if participant is None:
            raise NotFound(f"study {study_id!r} has no participant {participant_id}")
        tasks = []
        for ts in repo.task_sessions_of(s, participant_id=participant.id):
            state = core.SessionState.from_json(ts.state_json)
            b = core.belief(state)
            truth = _truth_mask(study.tasks[ts.task_index])
            tasks.append({
                "task_index": ts.task_index, "task": study.tasks[ts.task_index]["key"], "phase": state.phase,
                "n_observations": len(state.learning_records), "entropy": b.entropy,
                "map_formula": space.text_of(b.map_mask), "map_description": space.describe(b.map_mask),
                "similarity": None if truth is None else b.similarity(truth),
                "map_similarity": None if truth is None else b.map_similarity(truth),
                "top": [{"formula": space.text_of(m), "description": space.describe(m), "p": p} for m, p in b.top(top)],
            })
        return {"participant_id": participant.id, "condition": participant.condition, "stage": participant.stage,
                "tasks": tasks}


# ====================================================================== exports

EXPORTS = ("participants", "events", "beliefs", "questionnaire")
PARTICIPANT_COLUMNS = [
    "participant_id", "study_id", "condition", "pilot", "stage", "task_index", "prolific_pid", "external_study_id",
    "external_session_id", "consent_at", "consent_version", "completion_code", "created_at", "last_activity_at",
    "finished_at", "n_events", "seed",
]
EVENT_COLUMNS = [
    "participant_id", "seq", "created_at", "kind", "task_index", "task", "step_kind", "step_index", "object",
    "labels", "robot_events", "trace", "acceptable", "p_acceptable", "client_event_id", "app_version", "payload",
]
BELIEF_COLUMNS = [
    "participant_id", "condition", "task_index", "task", "step", "record_kind", "acceptable", "trace", "entropy",
    "map_formula", "map_description", "similarity", "map_similarity",
] + [f"top{i}_{part}" for i in range(1, 6) for part in ("formula", "p")]
QUESTIONNAIRE_COLUMNS = ["participant_id", "condition", "item_id", "item_kind", "item_text", "answer", "answered_at"]
EXPORT_COLUMNS = {"participants": PARTICIPANT_COLUMNS, "events": EVENT_COLUMNS, "beliefs": BELIEF_COLUMNS,
                  "questionnaire": QUESTIONNAIRE_COLUMNS}


def _json(value: Any) -> str | None:
    return None if value is None else json.dumps(value, separators=(",", ":"))


def export_rows(ctx: Context, study_id: str, name: str) -> Iterator[list[Any]]:
    """The rows of one export, header first; checks the study before the first row is produced."""
    if name not in EXPORTS:
        raise NotFound(f"no export named {name!r}; expected one of {', '.join(EXPORTS)}")
    with ctx.db.read() as s:
        _study(s, study_id)
    return _export_rows(ctx, study_id, name)


def _export_rows(ctx: Context, study_id: str, name: str) -> Iterator[list[Any]]:
    yield EXPORT_COLUMNS[name]
    with ctx.db.read() as s:
        study = _study(s, study_id)
        if name == "participants":
            for p in repo.list_participants(s, study_id=study_id):
                yield [p.id, p.study_id, p.condition, p.pilot, p.stage, p.task_index, p.prolific_pid,
                       p.external_study_id, p.external_session_id, _iso(p.consent_at), p.consent_version,
                       p.completion_code, _iso(p.created_at), _iso(p.last_activity_at), _iso(p.finished_at),
                       p.n_events, p.seed]
        elif name == "events":
            for e in repo.iter_study_events(s, study_id=study_id):
                pl = e.payload or {}
                task = None if e.task_index is None else study.tasks[e.task_index]["key"]
                yield [e.participant_id, e.seq, _iso(e.created_at), e.kind, e.task_index, task, e.step_kind,
                       e.step_index, pl.get("object"), _json(pl.get("labels")), _json(pl.get("events")),
                       _json(pl.get("trace")), pl.get("acceptable"), pl.get("p_acceptable"), e.client_event_id,
                       e.app_version, _json(pl)]
        elif name == "beliefs":
            yield from _belief_rows(s, study)
        else:
            items = {item["id"]: item for item in study.questionnaire}
            conditions = {p.id: p.condition for p in repo.list_participants(s, study_id=study_id)}
            for e in repo.iter_study_events_of_kind(s, study_id=study_id, kind="questionnaire"):
                for item_id, answer in (e.payload.get("answers") or {}).items():
                    item = items.get(item_id, {})
                    yield [e.participant_id, conditions.get(e.participant_id), item_id, item.get("kind"),
                           item.get("text"), answer, _iso(e.created_at)]


def _belief_rows(s: Any, study: StudyRow) -> Iterator[list[Any]]:
    space = get_domain("dinner").clause_space
    conditions = {p.id: p.condition for p in repo.list_participants(s, study_id=study.id)}
    for ts in repo.iter_study_task_sessions(s, study_id=study.id):
        state = core.SessionState.from_json(ts.state_json)
        truth = _truth_mask(study.tasks[ts.task_index])
        records: list[core.Record | None] = [None, *state.learning_records]
        for step, (record, b) in enumerate(zip(records, core.beliefs_by_step(state))):
            top = b.top(5)
            cells: list[Any] = []
            for i in range(5):
                cells += [space.text_of(top[i][0]), top[i][1]] if i < len(top) else [None, None]
            yield [ts.participant_id, conditions.get(ts.participant_id), ts.task_index,
                   study.tasks[ts.task_index]["key"], step, None if record is None else record.kind,
                   None if record is None else record.acceptable,
                   None if record is None else _json([sorted(x) for x in record.trace]),
                   b.entropy, space.text_of(b.map_mask), space.describe(b.map_mask),
                   None if truth is None else b.similarity(truth),
                   None if truth is None else b.map_similarity(truth), *cells]
