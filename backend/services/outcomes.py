"""How a participant's study ended (their outcome) and the code they are shown for it.

Prolific takes one completion code per outcome, each with its own action (approve, return, screen out), so a
study may set a code for each: completed, declined consent, failed the comprehension quiz, failed an attention
check, timed out, withdrew. Each is optional; a study made before per-outcome codes keeps its single
screened_out_code, used for every screened-out outcome without its own code.
"""

from __future__ import annotations

import secrets

from ..db.tables import ParticipantRow, StudyRow

# outcome -> the study field holding its code (the order is the order experimenters see them in)
OUTCOME_CODE_FIELDS = {
    "completed": "completion_code",
    "declined_consent": "declined_consent_code",
    "comprehension": "failed_quiz_code",
    "attention": "failed_attention_code",
    "timeout": "timed_out_code",
    "withdrew": "withdrew_code",
}

OUTCOMES = tuple(OUTCOME_CODE_FIELDS)

# Outcomes that the older single screened_out_code stood for.
SCREENED_OUT = ("declined_consent", "comprehension", "attention", "timeout")

OUTCOME_WORDS = {
    "completed": "completed the study",
    "declined_consent": "declined consent",
    "comprehension": "failed the comprehension quiz",
    "attention": "completed but failed an attention check",
    "timeout": "timed out (idle past the study's limit)",
    "withdrew": "withdrew",
}


def outcome_of(participant: ParticipantRow) -> str | None:
    """The participant's outcome, or None while under way (or for an erased participant)."""
    if participant.stage == "done":
        return "attention" if participant.attention_failed else "completed"
    reason = participant.end_reason
    return reason if reason in OUTCOME_CODE_FIELDS else None


def study_code(study: StudyRow, outcome: str) -> str | None:
    """The code the study sets for an outcome (the old screened_out_code for screened-out outcomes without one)."""
    code = getattr(study, OUTCOME_CODE_FIELDS[outcome])
    if code is None and outcome in SCREENED_OUT:
        code = study.screened_out_code
    return code


def code_to_show(study: StudyRow, outcome: str) -> str | None:
    """The code a participant is given for an outcome: the study's; a finisher without one gets a fresh code
    (a failed attention check counts as finishing unless the study gives that outcome its own code)."""
    code = study_code(study, outcome)
    if code is None and outcome in ("completed", "attention"):
        code = study.completion_code or secrets.token_hex(4).upper()
    return code
