"""Tables: studies, participants, one teaching session per participant and task, and the append-only event log."""

from __future__ import annotations

import secrets
from datetime import datetime, timezone
from typing import Any

from sqlalchemy import (JSON, Boolean, DateTime, Float, ForeignKey, Integer, LargeBinary, MetaData, String, Text,
                        UniqueConstraint, false, text, true)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

# Deterministic constraint names so that migrations (batch mode on SQLite) can refer to them.
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def new_uid() -> str:
    """A participant's uid: 128 random bits as hex, unique across databases (it names their recordings)."""
    return secrets.token_hex(16)


def utcnow() -> datetime:
    """The current time in UTC (timezone-aware)."""
    return datetime.now(timezone.utc)


class Base(DeclarativeBase):
    """Declarative base with the naming convention above."""

    metadata = MetaData(naming_convention=NAMING)


class StudyRow(Base):
    """A study: its tasks, conditions, counts, questionnaire and status."""

    __tablename__ = "studies"

    id: Mapped[str] = mapped_column(String(64), primary_key=True)
    name: Mapped[str] = mapped_column(String(200))
    tasks: Mapped[list[dict[str, Any]]] = mapped_column(JSON)
    conditions: Mapped[list[str]] = mapped_column(JSON)
    assignment: Mapped[str] = mapped_column(String(16))
    n_practice: Mapped[int] = mapped_column(Integer)
    n_demonstrations: Mapped[int] = mapped_column(Integer)
    n_queries: Mapped[int] = mapped_column(Integer)
    n_tests: Mapped[int] = mapped_column(Integer)
    prior: Mapped[str] = mapped_column(String(64))
    criterion: Mapped[str] = mapped_column(String(64))
    questionnaire: Mapped[list[dict[str, Any]]] = mapped_column(JSON)
    consent_text: Mapped[str] = mapped_column(Text)
    consent_version: Mapped[str] = mapped_column(String(64))
    completion_url: Mapped[str | None] = mapped_column(String(500), nullable=True)
    status: Mapped[str] = mapped_column(String(16), default="draft")
    pilot: Mapped[bool] = mapped_column(Boolean, default=False)
    # Study operations (docs/running-a-study.md): study-level codes, counterbalancing, checks, timeouts.
    completion_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    screened_out_code: Mapped[str | None] = mapped_column(String(64), nullable=True)  # before per-outcome codes
    # One code per outcome (services/outcomes.py), each optional.
    declined_consent_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    failed_quiz_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    failed_attention_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    timed_out_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    withdrew_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    task_order: Mapped[str] = mapped_column(String(16), default="fixed", server_default="fixed")
    quiz: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list, server_default="[]")
    quiz_max_attempts: Mapped[int] = mapped_column(Integer, default=2, server_default="2")
    timeout_minutes: Mapped[int | None] = mapped_column(Integer, nullable=True)
    # When timeout_minutes last changed: a new limit counts only idleness after it (None: since creation).
    timeout_changed_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    # Reconciliation with Prolific (services/prolific.py): the last uploaded submissions export, the bonus rule.
    prolific_submissions: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, nullable=True)
    prolific_uploaded_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    bonus_rule: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    archived_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)  # hidden from the list
    robot_speed: Mapped[float] = mapped_column(Float, default=1.0, server_default=text("1.0"))  # playback rate 1-3
    places: Mapped[int | None] = mapped_column(Integer, nullable=True)  # participants it takes (None: no limit)
    # The participant page's settings (services/page_settings.py): the structured consent form, links without a
    # PROLIFIC_PID, whether a failed quiz names the wrong answers.
    consent_form: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict, server_default="{}")
    allow_anonymous: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    quiz_feedback: Mapped[bool] = mapped_column(Boolean, default=True, server_default=true())
    # The learner's assumed verdict-flip probability in [0, 0.5) (core.belief): 0 is the authors' learner.
    flip_rate: Mapped[float] = mapped_column(Float, default=0.0, server_default=text("0.0"))
    # A study's own objects (tableteach.scenes.SceneSpec.to_json: name, shape, colour, size, slot); None: the dinner.
    objects: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow, onupdate=utcnow)


class ParticipantRow(Base):
    """A participant: secret token, uid, external ids, consent, condition, stage and completion."""

    __tablename__ = "participants"
    __table_args__ = (UniqueConstraint("study_id", "prolific_pid", name="uq_participants_study_external"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    token: Mapped[str] = mapped_column(String(64), unique=True, index=True)
    uid: Mapped[str] = mapped_column(String(32), unique=True, default=new_uid)
    # SHA-256 of the secret in the HttpOnly cookie of the browser that joined: resuming by external id needs it
    # (or the same external session id).
    browser_digest: Mapped[str | None] = mapped_column(String(64), nullable=True)
    study_id: Mapped[str] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    prolific_pid: Mapped[str | None] = mapped_column(String(128), nullable=True)
    external_study_id: Mapped[str | None] = mapped_column(String(128), nullable=True)
    external_session_id: Mapped[str | None] = mapped_column(String(128), nullable=True)
    condition: Mapped[str] = mapped_column(String(16))
    seed: Mapped[int] = mapped_column(Integer)
    pilot: Mapped[bool] = mapped_column(Boolean, default=False)
    stage: Mapped[str] = mapped_column(String(16), default="consent")
    task_index: Mapped[int] = mapped_column(Integer, default=0)
    consent_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    consent_version: Mapped[str | None] = mapped_column(String(64), nullable=True)
    completion_code: Mapped[str | None] = mapped_column(String(64), nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    last_activity_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    # Attention telemetry from the page (services/attention.py): {"tab_hidden": n, "window_blur": n, "paste": n}.
    attention_signals: Mapped[dict[str, int]] = mapped_column(JSON, default=dict, server_default="{}")
    n_events: Mapped[int] = mapped_column(Integer, default=0)
    task_order: Mapped[list[int] | None] = mapped_column(JSON, nullable=True)  # study task indices; None: as listed
    quiz_failures: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    attention_failed: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    # Why a participant left before the end: declined_consent, withdrew, comprehension, timeout (None otherwise).
    # An erased participant keeps only this row (stage "erased", no personal data) so that its id is never reused.
    end_reason: Mapped[str | None] = mapped_column(String(32), nullable=True)
    version: Mapped[int] = mapped_column(Integer, nullable=False)

    # Optimistic locking: two writers that both read version n cannot both store version n + 1.
    __mapper_args__ = {"version_id_col": version}


class TaskSessionRow(Base):
    """One teaching session (one task) of a participant: the core's state and the step in progress."""

    __tablename__ = "task_sessions"
    __table_args__ = (UniqueConstraint("participant_id", "task_index", name="uq_task_sessions_participant_task"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"), index=True)
    task_index: Mapped[int] = mapped_column(Integer)
    state_json: Mapped[str] = mapped_column(Text)
    demo_placed: Mapped[list[str]] = mapped_column(JSON, default=list)
    demo_trace: Mapped[list[list[str]]] = mapped_column(JSON, default=list)
    execution: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    # Bumped by every update (optimistic locking, as on participants): a poll compares it to tell "nothing new".
    version: Mapped[int] = mapped_column(Integer, nullable=False, server_default="1")

    __mapper_args__ = {"version_id_col": version}


class EventRow(Base):
    """One entry of a participant's append-only log; client_event_id makes retries idempotent."""

    __tablename__ = "events"
    __table_args__ = (
        UniqueConstraint("participant_id", "seq", name="uq_events_participant_seq"),
        UniqueConstraint("participant_id", "client_event_id", name="uq_events_participant_client_id"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"), index=True)
    seq: Mapped[int] = mapped_column(Integer)
    client_event_id: Mapped[str | None] = mapped_column(String(128), nullable=True)
    request_digest: Mapped[str | None] = mapped_column(String(64), nullable=True)
    kind: Mapped[str] = mapped_column(String(32))
    task_index: Mapped[int | None] = mapped_column(Integer, nullable=True)
    step_kind: Mapped[str | None] = mapped_column(String(16), nullable=True)
    step_index: Mapped[int | None] = mapped_column(Integer, nullable=True)
    payload: Mapped[dict[str, Any]] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    app_version: Mapped[str] = mapped_column(String(32))


class ErasureRow(Base):
    """Audit entry of an erased participant: who erased, when and why; no personal data."""

    __tablename__ = "erasures"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    study_id: Mapped[str] = mapped_column(String(64), index=True)
    participant_id: Mapped[int] = mapped_column(Integer)
    erased_by: Mapped[str] = mapped_column(String(64))
    reason: Mapped[str] = mapped_column(String(32))
    pilot: Mapped[bool] = mapped_column(Boolean, default=False)
    erased_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class JobRow(Base):
    """Work that must happen after a participant's action (services.runtime): written in the action's own
    transaction, claimed by a live app process for `claimed_until`, deleted once done, retried with backoff."""

    __tablename__ = "jobs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    kind: Mapped[str] = mapped_column(String(32))
    participant_id: Mapped[int] = mapped_column(ForeignKey("participants.id", ondelete="CASCADE"), index=True)
    task_index: Mapped[int | None] = mapped_column(Integer, nullable=True)
    payload: Mapped[dict[str, Any]] = mapped_column(JSON)
    due_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    claimed_by: Mapped[str | None] = mapped_column(String(64), nullable=True)
    claimed_until: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    last_error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ExperimenterRow(Base):
    """A person who runs studies: their name, role (owner, experimenter, analyst) and argon2 password hash."""

    __tablename__ = "experimenters"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))
    password_hash: Mapped[str | None] = mapped_column(String(200), nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    disabled_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class ApiTokenRow(Base):
    """One person's API token, kept as its SHA-256: when it expires and whether it was revoked."""

    __tablename__ = "api_tokens"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    experimenter_id: Mapped[int] = mapped_column(ForeignKey("experimenters.id", ondelete="CASCADE"), index=True)
    digest: Mapped[str] = mapped_column(String(64), unique=True)
    label: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    expires_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class AuditRow(Base):
    """One experimenter write: who (name and role), what (method, path, answer status), when, from where."""

    __tablename__ = "audit_log"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow, index=True)
    actor: Mapped[str] = mapped_column(String(64))
    role: Mapped[str] = mapped_column(String(16))
    method: Mapped[str] = mapped_column(String(8))
    path: Mapped[str] = mapped_column(String(500))
    status: Mapped[int] = mapped_column(Integer)
    client: Mapped[str] = mapped_column(String(64))


class RecordingBlobRow(Base):
    """The bytes of one recording file, named by their SHA-256: a file several participants share is kept once."""

    __tablename__ = "recording_blobs"

    digest: Mapped[str] = mapped_column(String(64), primary_key=True)
    size: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class RecordingFileRow(Base):
    """One participant's recording file (participant-<uid>/task-<i>/<kind>-<j>.<suffix>) and the bytes it holds."""

    __tablename__ = "recording_files"

    name: Mapped[str] = mapped_column(String(200), primary_key=True)
    participant_uid: Mapped[str] = mapped_column(String(32), index=True)
    digest: Mapped[str] = mapped_column(ForeignKey("recording_blobs.digest"), index=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
