"""A study's participant-page settings, kept apart from the rest of its definition: the structured consent form
(who runs the study, contact, ethics approval, duration, payment, what is recorded, retention, withdrawal),
whether a link without a PROLIFIC_PID may join anonymously, and whether a failed quiz names the wrong answers."""

from __future__ import annotations

import hashlib
import json
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from .plain_words import shown

# field -> (heading on the consent page, longest text accepted)
CONSENT_FORM_FIELDS: dict[str, tuple[str, int]] = {
    "researcher": ("Who is running this study", 200),
    "institution": ("Institution", 200),
    "contact": ("Questions or complaints", 500),
    "ethics_approval": ("Ethics approval", 300),
    "duration": ("How long it takes", 200),
    "payment": ("Payment", 300),
    "recorded": ("What we record", 2000),
    "retention": ("How long we keep the data", 1000),
    "withdrawal": ("Your right to withdraw", 1000),
}
# What the page says for fields the study leaves empty (true of every study on this server).
CONSENT_DEFAULTS = {
    "recorded": "The objects you choose and when, your verdicts on the robot's attempts, your answers to the "
                "questions, how long each step takes, and whether this page was hidden, left or pasted into while "
                "you took part. Your Prolific ID is stored to pay you; your name is never asked for.",
    "withdrawal": "You may stop at any time, without giving a reason, with the \"Withdraw\" link at the top of every "
                  "page: your recorded actions and answers are then deleted, and we keep only the fact that you "
                  "withdrew.",
}
SETTINGS = ("consent_form", "allow_anonymous", "quiz_feedback")


class ConsentFormIn(BaseModel):
    """The consent page's structured sections; empty ones are left out (what is recorded and the right to
    withdraw have defaults that are true of every study on this server)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    researcher: str | None = Field(None, max_length=200, description="the researcher(s) running the study")
    institution: str | None = Field(None, max_length=200)
    contact: str | None = Field(None, max_length=500, description="how to reach the researchers (e-mail)")
    ethics_approval: str | None = Field(None, max_length=300, description="the approving board and reference")
    duration: str | None = Field(None, max_length=200, description="empty: the page's own estimate")
    payment: str | None = Field(None, max_length=300)
    recorded: str | None = Field(None, max_length=2000, description="what is recorded")
    retention: str | None = Field(None, max_length=1000, description="how long the data are kept, and where")
    withdrawal: str | None = Field(None, max_length=1000, description="the right to withdraw")


class _Problems(Protocol):
    def add(self, field: str, message: str) -> None: ...


class _Study(Protocol):
    consent_form: dict[str, Any]
    allow_anonymous: bool
    quiz_feedback: bool
    consent_text: str
    consent_version: str


def check_page_settings(spec: dict[str, Any], problems: _Problems) -> dict[str, Any]:
    """The page settings' column values from a study specification; each unacceptable field is added to problems."""
    form = spec.get("consent_form") or {}
    clean: dict[str, str] = {}
    if not isinstance(form, dict):
        problems.add("consent_form", f"expected an object with some of {', '.join(CONSENT_FORM_FIELDS)}, "
                     f"got {shown(form)}")
        form = {}
    for name, value in form.items():
        if name not in CONSENT_FORM_FIELDS:
            problems.add(f"consent_form.{name}", f"is not a consent form field; expected one of "
                         f"{', '.join(CONSENT_FORM_FIELDS)}")
            continue
        longest = CONSENT_FORM_FIELDS[name][1]
        if value is None or value == "":
            continue
        if not isinstance(value, str) or len(value) > longest:
            problems.add(f"consent_form.{name}", f"must be text of at most {longest} characters, got {shown(value)}")
            continue
        clean[name] = value.strip()
    flags = {}
    for name, default in (("allow_anonymous", False), ("quiz_feedback", True)):
        value = spec.get(name, default)
        if not isinstance(value, bool):
            problems.add(name, f"must be true or false, got {shown(value)}")
            value = default
        flags[name] = value
    return {"consent_form": clean, **flags}


def page_settings_view(study: _Study) -> dict[str, Any]:
    """The page settings as the experimenter API shows them."""
    return {"consent_form": dict(study.consent_form or {}), "allow_anonymous": bool(study.allow_anonymous),
            "quiz_feedback": bool(study.quiz_feedback)}


def consent_sections(study: _Study) -> list[dict[str, str]]:
    """The consent page's sections in order, [{key, heading, text}], the study's own words or the defaults."""
    form = study.consent_form or {}
    out = []
    for name, (heading, _longest) in CONSENT_FORM_FIELDS.items():
        text = form.get(name) or CONSENT_DEFAULTS.get(name)
        if text:
            out.append({"key": name, "heading": heading, "text": text})
    return out


def consent_digest(study: _Study) -> str:
    """SHA-256 (first 16 hex digits) of exactly what the consent page shows: recorded with each consent, so the
    words a participant agreed to can be told apart even if a study's version was not raised after an edit."""
    shown = json.dumps([study.consent_text, study.consent_version, consent_sections(study)], sort_keys=True)
    return hashlib.sha256(shown.encode()).hexdigest()[:16]
