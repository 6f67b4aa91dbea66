"""Joining a study, consent, instructions and the questionnaire."""

from __future__ import annotations

import hashlib
import hmac
import itertools
import secrets
from collections import Counter
from datetime import timedelta
from typing import Any

from ..config import Settings
from ..db import repository as repo
from ..db.tables import StudyRow, utcnow
from ..errors import Conflict, InvalidInput, NotAuthenticated, NotFound, ResumeRefused, StudyFull
from .context import Context, app_version, commit
from .outcomes import code_to_show
from .plain_words import shown
from .page_settings import consent_digest
from .state import Action, act, end_participation, require_stage, state_view, task_sequence
from .studies import ITEM_KINDS
from .teaching import begin_task, complete


def _assign(s: Any, study: StudyRow, settings: Settings) -> tuple[str, list[int] | None]:
    """The new participant's condition and task order (None: the tasks as listed).

    Conditions: random, or balanced over the participants who finished or were active recently. Task order:
    fixed, random, or balanced (every order of the tasks, crossed with the balanced conditions, so that the
    live participants' counts per condition x order differ by at most one). Balance is over those who consented;
    those who joined but have not consented (yet) only break ties, so joins that never consent (a flood of the
    public link) cannot push real participants out of balance. Remaining ties are broken at random."""
    rng = secrets.SystemRandom()
    n_tasks = len(study.tasks)
    since = utcnow() - timedelta(minutes=settings.active_minutes)
    live: list[tuple[str, list[int] | None, bool]] = []
    if study.assignment == "balanced" or study.task_order == "balanced":
        live = repo.live_assignments(s, study_id=study.id, active_since=since, pilot=study.pilot)
    conditions = list(study.conditions)
    if study.assignment == "random" or len(conditions) == 1:
        conditions = [rng.choice(conditions)]
    if study.task_order == "balanced":
        orders = [list(o) for o in itertools.permutations(range(n_tasks))]
    else:
        orders = [list(range(n_tasks))]
    consented = Counter((c, tuple(o) if o else tuple(range(n_tasks))) for c, o, yes in live if yes)
    waiting = Counter((c, tuple(o) if o else tuple(range(n_tasks))) for c, o, yes in live if not yes)

    def load(cell: tuple[str, list[int]]) -> tuple[int, int]:
        key = (cell[0], tuple(cell[1]))
        return consented[key], waiting[key]

    cells = [(c, o) for c in conditions for o in orders]
    fewest = min(load(cell) for cell in cells)
    condition, order = rng.choice([cell for cell in cells if load(cell) == fewest])
    if study.task_order == "random":
        order = rng.sample(range(n_tasks), n_tasks)
    return condition, (None if study.task_order == "fixed" else order)


RESUME_REFUSED = ("This participant id has already started this study. To continue, open the study link again "
                  "in the same browser, or from the same Prolific session.")


def browser_digest(secret: str) -> str:
    """What is stored of a browser's secret (the HttpOnly cookie set at join): its SHA-256."""
    return hashlib.sha256(secret.encode()).hexdigest()


def _may_resume(existing: Any, session_id: str | None, browser_secret: str | None) -> bool:
    """Whether this request proves to be the participant who joined: the same external session or browser."""
    if session_id and existing.external_session_id and hmac.compare_digest(session_id, existing.external_session_id):
        return True
    return bool(browser_secret and existing.browser_digest
                and hmac.compare_digest(browser_digest(browser_secret), existing.browser_digest))


def join_study(
    ctx: Context, study_id: str, *, prolific_pid: str | None = None, external_study_id: str | None = None,
    external_session_id: str | None = None, browser_secret: str | None = None,
) -> tuple[dict[str, Any], bool]:
    """A new participant, or the one who joined before with this external id, and whether it is new.

    An external id alone is not enough to resume (ids are shown on the dashboard and exported): the request
    must carry the external session id the participant first came with, or come from the same browser
    (browser_secret, from the cookie set at join). Otherwise ResumeRefused (a Conflict), which says nothing
    about that participant."""
    with ctx.db.write() as s:
        study = repo.get_study(s, study_id=study_id, for_update=True)
        if study is None:
            raise NotFound(f"no study with id {study_id!r}")
        if prolific_pid:
            existing = repo.find_participant_by_external_id(s, study_id=study_id, prolific_pid=prolific_pid)
            if existing is not None:
                if not _may_resume(existing, external_session_id, browser_secret):
                    raise ResumeRefused(RESUME_REFUSED)
                return state_view(s, existing, study), False
        if study.status != "open":
            raise Conflict(f"study {study_id!r} is {study.status}; participants can join only while it is open")
        if study.places is not None:
            since = utcnow() - timedelta(minutes=ctx.settings.active_minutes)
            taken = repo.places_taken(s, study_id=study.id, active_since=since, pilot=study.pilot)
            if taken >= study.places:
                raise StudyFull(f"study {study_id!r} is full: it takes {study.places} participant(s) and {taken} "
                                "have finished or are under way; a place frees when one leaves or goes idle")
        condition, task_order = _assign(s, study, ctx.settings)
        participant = repo.add_participant(s, values={
            "token": secrets.token_urlsafe(24),
            "study_id": study.id,
            "prolific_pid": prolific_pid or None,
            "external_study_id": external_study_id or None,
            "external_session_id": external_session_id or None,
            "browser_digest": browser_digest(browser_secret) if browser_secret else None,
            "condition": condition,
            "task_order": task_order,
            "seed": secrets.randbelow(2**31 - 1000),
            "pilot": study.pilot,
            "stage": "consent",
            "task_index": 0,
            "n_events": 0,
        })
        repo.append_event(s, participant=participant, kind="joined", app_version=app_version(), payload={
            "condition": participant.condition, "task_order": task_order, "prolific_pid": prolific_pid,
            "external_study_id": external_study_id,
            "external_session_id": external_session_id,
        })
        commit(s)
        return state_view(s, participant, study), True


def participant_id_of(ctx: Context, token: str) -> int:
    """The number of the participant whose token this is (one query; NotAuthenticated for an unknown token).

    For the long-lived connections, which need to know whose they are but not the whole state."""
    with ctx.db.read() as s:
        found = repo.get_participant_and_study(s, token=token)
        if found is None:
            raise NotAuthenticated("unknown participant token")
        return int(found[0].id)


def give_consent(ctx: Context, token: str, *, agree: bool, consent_version: str,
                 key: str | None = None) -> dict[str, Any]:
    """Record consent (or its refusal, which withdraws the participant)."""
    def run(a: Action) -> None:
        require_stage(a, "consent")
        if consent_version != a.study.consent_version:
            raise Conflict(f"consent text version {consent_version!r} is not the current one "
                           f"({a.study.consent_version!r}); reload the page and read it again")
        now = utcnow()
        a.log("consent", {"agree": agree, "consent_version": consent_version, "at": now.isoformat(),
                          "consent_digest": consent_digest(a.study)})
        if agree:
            a.participant.consent_at = now
            a.participant.consent_version = consent_version
            a.participant.stage = "instructions"
        else:
            a.participant.stage = "withdrawn"
            a.participant.end_reason = "declined_consent"
            a.participant.finished_at = now
            a.participant.completion_code = code_to_show(a.study, "declined_consent")

    return act(ctx, token, "consent", {"agree": agree, "version": consent_version}, key, run)


def finish_instructions(ctx: Context, token: str, *, key: str | None = None) -> dict[str, Any]:
    """The participant has read the instructions: the first task begins."""
    def run(a: Action) -> None:
        require_stage(a, "instructions")
        a.log("instructions_read", {})
        if a.study.quiz:
            a.participant.stage = "quiz"
        else:
            begin_task(a, task_sequence(a.study, a.participant)[0])

    return act(ctx, token, "instructions", {}, key, run)


def answer_quiz(ctx: Context, token: str, *, answers: dict[str, Any], key: str | None = None) -> dict[str, Any]:
    """The comprehension quiz: all correct starts the first task; a wrong attempt past the study's limit screens
    the participant out."""
    def run(a: Action) -> None:
        require_stage(a, "quiz")
        items = {item["id"]: item for item in a.study.quiz}
        unknown = sorted(set(answers) - set(items))
        if unknown:
            raise InvalidInput(f"unknown quiz item(s) {', '.join(map(repr, unknown))}; expected {', '.join(items)}")
        for item_id, item in items.items():
            value = answers.get(item_id)
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < len(item["options"]):
                raise InvalidInput(f"answer to quiz item {item_id!r} must be the number of an option, from 0 to "
                                   f"{len(item['options']) - 1}, got {shown(value)}")
        wrong = [i for i, item in items.items() if answers[i] != item["correct"]]
        attempt = a.participant.quiz_failures + 1
        a.log("quiz", {"answers": dict(answers), "wrong": wrong, "passed": not wrong, "attempt": attempt})
        if not wrong:
            begin_task(a, task_sequence(a.study, a.participant)[0])
            return
        a.participant.quiz_failures = attempt
        if attempt >= a.study.quiz_max_attempts:
            a.participant.completion_code = code_to_show(a.study, "comprehension")
            end_participation(a.s, a.participant, stage="screened_out", reason="comprehension")

    return act(ctx, token, "quiz", {"answers": answers}, key, run)


def _check_answer(item: dict[str, Any], value: Any) -> Any:
    bounds = ITEM_KINDS[item["kind"]]
    if bounds is None:
        if not isinstance(value, str) or len(value) > 5000:
            raise InvalidInput(f"answer to {item['id']!r} must be text of at most 5000 characters")
        return value
    low, high = bounds
    if not isinstance(value, int) or isinstance(value, bool) or not low <= value <= high:
        raise InvalidInput(f"answer to {item['id']!r} must be a whole number from {low} to {high}, got {shown(value)}")
    return value


def answer_questionnaire(ctx: Context, token: str, *, answers: dict[str, Any],
                         key: str | None = None) -> dict[str, Any]:
    """Store the questionnaire's answers; the participant is then done and gets a completion code."""
    def run(a: Action) -> None:
        require_stage(a, "questionnaire")
        items = {item["id"]: item for item in a.study.questionnaire}
        unknown = sorted(set(answers) - set(items))
        if unknown:
            raise InvalidInput(f"unknown questionnaire item(s) {', '.join(map(repr, unknown))}; "
                               f"expected some of {', '.join(items)}")
        missing = [i for i, item in items.items() if item["required"] and answers.get(i) in (None, "")]
        if missing:
            raise InvalidInput(f"required questionnaire item(s) not answered: {', '.join(missing)}")
        clean = {i: _check_answer(items[i], v) for i, v in answers.items() if v is not None}
        attention = {i: clean.get(i) == item["expected"] for i, item in items.items() if item["kind"] == "attention"}
        if not all(attention.values()):
            a.participant.attention_failed = True  # flagged in the exports and on the dashboard, never dropped
        a.log("questionnaire", {"answers": clean, "attention": attention})
        complete(a)

    return act(ctx, token, "questionnaire", {"answers": answers}, key, run)
