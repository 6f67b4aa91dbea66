"""The experimenter's help for one participant: restore one who timed out or was screened out, and help a stuck one
on to the next stage. Each is an event in the participant's log (who, what, from where), exported with the rest.
"""

from __future__ import annotations

from typing import Any

from ..db import repository as repo
from ..db.tables import utcnow
from ..errors import Conflict, NotFound
from .context import Context
from .lifecycle import expire_timeouts
from .monitoring import participant_row
from .planning import session_of
from .state import Action, act, robot_key, task_sequence
from .teaching import begin_task, complete

# end_reason -> the stage a restored participant goes back to (None: worked out from their progress)
RESTORABLE = {"timeout": None, "comprehension": "quiz", "declined_consent": "consent"}

# stage -> what helping a participant on there does (in words, for the log and the API's answer)
HELP = {
    "instructions": "marked the instructions as read",
    "quiz": "let the participant past the comprehension quiz",
    "task": "ended the current task (the next task, or the questionnaire, follows)",
    "questionnaire": "ended the questionnaire without the missing answers: the participant is done",
}


def _participant_token(ctx: Context, study_id: str, participant_id: int) -> str:
    with ctx.db.read() as s:
        if repo.get_study(s, study_id=study_id) is None:
            raise NotFound(f"no study with id {study_id!r}")
        participant = repo.get_participant(s, study_id=study_id, participant_id=participant_id)
        if participant is None:
            raise NotFound(f"study {study_id!r} has no participant {participant_id}")
        return participant.token


def _resume_stage(a: Action) -> str:
    """Where a timed-out participant was: consent, instructions, their current task or the questionnaire."""
    p = a.participant
    if p.consent_at is None:
        return "consent"
    sessions = {ts.task_index: ts for ts in repo.task_sessions_of(a.s, participant_id=p.id)}
    current = sessions.get(p.task_index)
    if current is None:
        return "instructions"
    if session_of(current.state_json).phase != "done":
        return "task"
    return "questionnaire"


def _answer(ctx: Context, study_id: str, participant_id: int) -> dict[str, Any]:
    with ctx.db.read() as s:
        participant = repo.get_participant(s, study_id=study_id, participant_id=participant_id)
        assert participant is not None
        return participant_row(participant, ctx.settings, utcnow())


def restore_participant(ctx: Context, study_id: str, participant_id: int, *, by: str) -> dict[str, Any]:
    """Bring back a participant who timed out, failed the quiz (with fresh attempts) or declined consent: they
    continue where they were, with no code yet, and the time-out counts from now. The event names `by`, the acting
    person."""
    token = _participant_token(ctx, study_id, participant_id)

    def run(a: Action) -> None:
        p = a.participant
        if p.end_reason not in RESTORABLE:
            raise Conflict(f"participant {participant_id} is at the {p.stage} stage and was not screened out or "
                           "timed out; expected a participant who timed out, failed the quiz or declined consent "
                           "(one who withdrew has no data left to continue with)")
        reason = p.end_reason
        stage = RESTORABLE[reason] or _resume_stage(a)
        p.stage, p.end_reason, p.finished_at, p.completion_code = stage, None, None, None
        if reason == "comprehension":
            p.quiz_failures = 0
        a.log("restored", {"by": by, "reason": reason, "stage": stage})

    act(ctx, token, "restore", {"participant_id": participant_id}, None, run)
    return _answer(ctx, study_id, participant_id)


def help_on(ctx: Context, study_id: str, participant_id: int, *, by: str) -> dict[str, Any]:
    """Move a stuck participant past the stage they are at (instructions, quiz, the current task or the
    questionnaire); consent stays theirs to give. The event names `by`, the acting person."""
    token = _participant_token(ctx, study_id, participant_id)
    expire_timeouts(ctx, study_id)  # one idle past the limit is screened out first: restore, then help

    def run(a: Action) -> None:
        p = a.participant
        if p.stage not in HELP:
            hint = ("; restore them first" if p.end_reason in RESTORABLE else "")
            raise Conflict(f"participant {participant_id} is at the {p.stage} stage, where there is nothing to help "
                           f"past{hint}; expected one at the instructions, the quiz, a task or the questionnaire"
                           + (" (consent is theirs to give)" if p.stage == "consent" else ""))
        stage = p.stage
        a.log("helped_on", {"by": by, "stage": stage, "task_index": p.task_index, "what": HELP[stage]})
        sequence = task_sequence(a.study, p)
        if stage == "instructions" and a.study.quiz:
            p.stage = "quiz"
        elif stage in ("instructions", "quiz"):
            begin_task(a, sequence[0])
        elif stage == "task":
            a.ctx.robot.close(robot_key(p, p.task_index))
            position = sequence.index(p.task_index)
            if position + 1 < len(sequence):
                begin_task(a, sequence[position + 1])
            elif a.study.questionnaire:
                p.stage = "questionnaire"
            else:
                complete(a)
        else:
            complete(a)

    act(ctx, token, "help", {"participant_id": participant_id}, None, run)
    return _answer(ctx, study_id, participant_id)
