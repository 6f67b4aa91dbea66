"""Leaving a study and erasing data: withdrawal, the experimenter's erasure, the pilot reset and timeouts.

Withdrawal and erasure delete a participant's events (their answers among them), teaching sessions (their
beliefs) and robot recordings. A withdrawn participant keeps a row that says only that they withdrew; an
erased one keeps a row with no personal data (stage "erased", shown nowhere) so that its id is never reused,
and the erasure is written to an audit log (who, when, why; no personal data).
"""

from __future__ import annotations

import logging
import secrets
from datetime import timedelta
from typing import Any

from ..db import repository as repo
from ..db.tables import ParticipantRow, utcnow
from ..errors import Conflict, NotFound
from .context import Context, commit, iso
from .outcomes import code_to_show
from .state import Action, act, end_participation, mark_timed_out, robot_key, timed_out
from .studies import study_row

log = logging.getLogger(__name__)



def delete_recordings_of(ctx: Context, participant_uid: str) -> None:
    """Delete one participant's robot recordings; a failure is logged (the database is already erased)."""
    try:
        ctx.store.delete_participant(participant_uid)
    except OSError:
        log.exception("could not delete the recordings of participant uid %s", participant_uid)


def _forget_robot(ctx: Context, participant: ParticipantRow, n_tasks: int) -> None:
    """Stop the robot's tables (and views) of the participant; nothing of theirs stays in the process."""
    for index in range(n_tasks):
        try:
            ctx.robot.close(robot_key(participant, index))
        except Exception:
            log.exception("could not close the robot table of participant %s task %s", participant.id, index)


def withdraw(ctx: Context, token: str, *, key: str | None = None) -> dict[str, Any]:
    """The participant withdraws: their recorded actions, answers, beliefs and recordings are deleted; the row
    keeps only that they withdrew. Withdrawing again changes nothing."""
    erased: list[str] = []  # the uid of the participant, once withdrawn

    def run(a: Action) -> None:
        if a.participant.stage == "withdrawn":
            return
        if a.participant.consent_at is None:
            raise Conflict(f"withdrawal is possible after consent; the participant is at the {a.participant.stage} "
                           "stage (to leave before consenting, decline consent)")
        erased.append(a.participant.uid)
        _forget_robot(ctx, a.participant, len(a.study.tasks))
        repo.delete_participant_data(a.s, participant_id=a.participant.id)
        p = a.participant
        p.completion_code, p.attention_failed, p.quiz_failures = code_to_show(a.study, "withdrew"), False, 0
        p.prolific_pid = p.external_study_id = p.external_session_id = None  # only the fact of withdrawal stays
        end_participation(a.s, p, stage="withdrawn", reason="withdrew", key=a.key, digest=a.digest)
        a.n_logged += 1

    state = act(ctx, token, "withdraw", {}, key, run)
    for uid in erased:
        delete_recordings_of(ctx, uid)
    return state


def _erase(ctx: Context, s: Any, participant: ParticipantRow, n_tasks: int, *, reason: str, by: str) -> None:
    """Delete everything a participant left and record who erased them (in the caller's transaction)."""
    _forget_robot(ctx, participant, n_tasks)
    repo.delete_participant_data(s, participant_id=participant.id)
    repo.add_erasure(s, values={"study_id": participant.study_id, "participant_id": participant.id,
                                "erased_by": by[:64], "reason": reason, "pilot": participant.pilot})
    p = participant
    p.stage, p.token = "erased", "erased-" + secrets.token_urlsafe(24)  # the old link stops working
    p.prolific_pid = p.external_study_id = p.external_session_id = None
    p.consent_at = p.consent_version = p.completion_code = None
    p.end_reason, p.n_events, p.finished_at = reason, 0, utcnow()


def erase_participant(ctx: Context, study_id: str, participant_id: int, *, by: str) -> None:
    """Erase one participant's data (idempotent: erasing an erased participant changes nothing); `by` is the
    acting person's name (accounts.Actor), kept in the erasure log."""
    with ctx.db.write() as s:
        study = study_row(s, study_id)
        participant = repo.get_participant(s, study_id=study_id, participant_id=participant_id, include_erased=True)
        if participant is None:
            raise NotFound(f"study {study_id!r} has no participant {participant_id}")
        if participant.stage == "erased":
            return
        uid = participant.uid
        _erase(ctx, s, participant, len(study.tasks), reason="erasure", by=by)
        commit(s)
    delete_recordings_of(ctx, uid)


def reset_pilot(ctx: Context, study_id: str, *, by: str) -> dict[str, Any]:
    """Erase every pilot participant of a study (the erasure log names `by`, the acting person); the others are
    not touched."""
    with ctx.db.write() as s:
        study = study_row(s, study_id)
        pilots = [p for p in repo.list_participants(s, study_id=study_id) if p.pilot]
        erased = [(p.id, p.uid) for p in pilots]
        for p in pilots:
            _erase(ctx, s, p, len(study.tasks), reason="pilot_reset", by=by)
        commit(s)
    for _, uid in erased:
        delete_recordings_of(ctx, uid)
    return {"study_id": study_id, "erased": [pid for pid, _ in erased]}


def erasure_log(ctx: Context, study_id: str) -> list[dict[str, Any]]:
    """A study's erasure audit entries."""
    with ctx.db.read() as s:
        study_row(s, study_id)
        return [{"participant_id": e.participant_id, "erased_by": e.erased_by, "reason": e.reason,
                 "pilot": e.pilot, "erased_at": iso(e.erased_at)} for e in repo.list_erasures(s, study_id=study_id)]


def expire_timeouts(ctx: Context, study_id: str) -> int:
    """Screen out the participants idle past the study's timeout (their data stay, flagged); how many."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        if not study.timeout_minutes:
            return 0
        since = utcnow() - timedelta(minutes=study.timeout_minutes)
        if not any(timed_out(study, p) for p in repo.stale_participants(s, study_id=study_id, idle_since=since)):
            return 0  # (a changed limit counts idleness from the change: state.timed_out)
    with ctx.db.write() as s:
        stale = [p for p in repo.stale_participants(s, study_id=study_id, idle_since=since) if mark_timed_out(s, p)]
        try:
            repo.commit(s)
        except repo.WriteConflict:
            return 0  # one of them acted meanwhile; the next look tries again
        for p in stale:
            ctx.notifier.publish(p.id)  # an open page shows that the study has ended for them
        return len(stale)
