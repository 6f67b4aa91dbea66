"""Reconciliation with Prolific: its submissions export (CSV) uploaded to a study, a table per Prolific id of
Prolific's status against ours with mismatches flagged, and a bonus file in Prolific's bulk-bonus format (one
line "participant id,amount" each) from the study's bonus rule (an amount per outcome)."""

from __future__ import annotations

import csv
import io
import re
from decimal import Decimal, InvalidOperation
from typing import Any

from ..db import repository as repo
from ..db.tables import utcnow
from ..errors import InvalidFields, InvalidInput
from .context import Context, commit, iso
from .outcomes import OUTCOMES, outcome_of
from .plain_words import shown
from .studies import study_row

# Prolific's submission statuses (its export writes them with spaces, its API with underscores).
STATUSES = ("ACTIVE", "AWAITING REVIEW", "APPROVED", "REJECTED", "RETURNED", "TIMED-OUT", "SCREENED OUT",
            "PARTIALLY APPROVED", "UNKNOWN")
# Header names of the columns read, as Prolific's export and its API spell them (lower case, _ as space).
COLUMNS = {"participant_id": ("participant id", "participant"), "status": ("status",),
           "submission_id": ("submission id", "id"), "entered_code": ("completion code", "entered code")}
PROLIFIC_ID = re.compile(r"^[A-Za-z0-9_.:\-]{1,128}$")
MAX_ROWS = 100_000
MAX_BONUS = Decimal("100.00")  # per participant, in the study's currency: a typo of 150 instead of 1.50 is refused


def _status(value: str) -> str | None:
    text = value.strip().upper().replace("_", " ")
    text = "TIMED-OUT" if text in ("TIMED OUT", "TIMEDOUT") else text
    return text if text in STATUSES else None


def parse_submissions(text: str) -> list[dict[str, str | None]]:
    """Prolific's submissions export as rows {participant_id, status, submission_id, entered_code}; InvalidFields
    names the row (as a spreadsheet numbers it, the header being row 1) and the column of every bad cell."""
    reader = csv.reader(io.StringIO(text.lstrip("\ufeff")))
    header = next(reader, None)
    if not header:
        raise InvalidFields([{"field": "file", "message": "is empty; expected Prolific's submissions export (CSV "
                                                          "with a header row: Participant id, Status, ...)"}])
    names = [h.strip().lower().replace("_", " ") for h in header]
    where = {key: next((names.index(n) for n in spellings if n in names), None) for key, spellings in COLUMNS.items()}
    missing = [COLUMNS[key][0].capitalize() for key in ("participant_id", "status") if where[key] is None]
    if missing:
        raise InvalidFields([{"field": "row 1", "message": f"has no column {' or '.join(missing)}; expected "
                              f"Prolific's submissions export (its header row has {', '.join(header[:6])}...)"}])
    rows: list[dict[str, str | None]] = []
    errors: list[dict[str, str]] = []
    seen: dict[str, int] = {}
    for number, cells in enumerate(reader, start=2):
        if not any(c.strip() for c in cells):
            continue
        if number > MAX_ROWS:
            raise InvalidFields([{"field": f"row {number}", "message": f"more than {MAX_ROWS} rows"}])

        def cell(key: str, cells: list[str] = cells) -> str:
            index = where[key]
            return cells[index].strip() if index is not None and index < len(cells) else ""

        pid, status = cell("participant_id"), cell("status")
        if not PROLIFIC_ID.match(pid):
            errors.append({"field": f"row {number}, column {header[where['participant_id'] or 0].strip()}",
                           "message": f"{shown(pid)} is not a Prolific participant id" if pid else "is empty"})
        elif pid in seen:
            errors.append({"field": f"row {number}, column {header[where['participant_id'] or 0].strip()}",
                           "message": f"{pid} is already on row {seen[pid]}"})
        if _status(status) is None:
            errors.append({"field": f"row {number}, column {header[where['status'] or 0].strip()}",
                           "message": f"{shown(status)} is not a Prolific status; expected one of "
                                      f"{', '.join(STATUSES)}"})
        seen.setdefault(pid, number)
        rows.append({"participant_id": pid, "status": _status(status), "submission_id": cell("submission_id") or None,
                     "entered_code": cell("entered_code") or None})
        if len(errors) >= 50:
            break
    if errors:
        raise InvalidFields(errors)
    return rows


def store_submissions(ctx: Context, study_id: str, rows: list[dict[str, str | None]]) -> dict[str, Any]:
    """Keep the study's latest submissions export (it replaces the earlier one); how many rows."""
    with ctx.db.write() as s:
        study = study_row(s, study_id, for_update=True)
        study.prolific_submissions = rows
        study.prolific_uploaded_at = utcnow()
        commit(s)
        return {"study_id": study_id, "n_submissions": len(rows), "uploaded_at": iso(study.prolific_uploaded_at)}


def upload_submissions(ctx: Context, study_id: str, text: str) -> dict[str, Any]:
    """Parse and keep Prolific's submissions export for a study."""
    with ctx.db.read() as s:
        study_row(s, study_id)
    return store_submissions(ctx, study_id, parse_submissions(text))


def _mismatch(status: str | None, ours: Any) -> str | None:
    """Why Prolific's status and ours disagree (None if they agree or it cannot be told yet)."""
    if ours is None:
        return "unknown here: this Prolific id never joined the study on this server"
    outcome = outcome_of(ours)
    if status is None:
        return "unknown on Prolific: not in the uploaded submissions" if outcome is not None else None
    if status == "RETURNED" and outcome in ("completed", "attention"):
        return "returned on Prolific but finished here"
    if status == "APPROVED" and outcome not in ("completed", "attention", None):
        return f"approved on Prolific but {outcome.replace('_', ' ')} here"
    if status == "APPROVED" and outcome is None:
        return "approved on Prolific but still under way here"
    if status in ("AWAITING REVIEW", "APPROVED") and outcome == "withdrew":
        return "submitted on Prolific but withdrew here"
    return None


def reconciliation(ctx: Context, study_id: str) -> dict[str, Any]:
    """One row per Prolific id, from the uploaded submissions and this study's participants: Prolific's status
    and entered code against our stage, outcome and code, with the mismatch in words."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        submissions = {r["participant_id"]: r for r in study.prolific_submissions or []}
        ours = {p.prolific_pid: p for p in repo.list_participants(s, study_id=study_id) if p.prolific_pid}
        out = []
        for pid in sorted(set(submissions) | set(ours)):
            sub, p = submissions.get(pid), ours.get(pid)
            status = None if sub is None else sub["status"]
            problem = _mismatch(status, p) if sub is not None or p is not None else None
            entered = None if sub is None else sub.get("entered_code")
            if problem is None and p is not None and entered and p.completion_code and entered != p.completion_code:
                problem = f"entered code {entered} on Prolific, but we showed {p.completion_code}"
            out.append({"prolific_pid": pid, "prolific_status": status, "entered_code": entered,
                        "submission_id": None if sub is None else sub.get("submission_id"),
                        "participant_id": None if p is None else p.id, "stage": None if p is None else p.stage,
                        "outcome": None if p is None else outcome_of(p),
                        "completion_code": None if p is None else p.completion_code,
                        "mismatch": problem})
        return {"study_id": study_id, "uploaded_at": iso(study.prolific_uploaded_at),
                "n_mismatches": sum(1 for r in out if r["mismatch"]), "rows": out}


def _amount(value: Any, field: str) -> Decimal:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise InvalidFields([{"field": field, "message": "must be an amount such as 1.50"}])
    try:
        amount = Decimal(str(value)).quantize(Decimal("0.01"))
    except InvalidOperation as exc:
        message = f"must be an amount such as 1.50, got {shown(value)}"
        raise InvalidFields([{"field": field, "message": message}]) from exc
    if not Decimal(0) <= amount <= MAX_BONUS:
        raise InvalidFields([{"field": field, "message": f"must be from 0 to {MAX_BONUS}, got {amount}"}])
    return amount


def set_bonus_rule(ctx: Context, study_id: str, amounts: dict[str, Any]) -> dict[str, Any]:
    """The study's bonus rule: an amount (in the study's Prolific currency) per outcome; outcomes left out get
    none."""
    unknown = sorted(set(amounts) - set(OUTCOMES))
    if unknown:
        raise InvalidFields([{"field": f"amounts.{k}", "message": f"is not an outcome; expected one of "
                                                                  f"{', '.join(OUTCOMES)}"} for k in unknown])
    rule = {k: str(_amount(v, f"amounts.{k}")) for k, v in amounts.items()}
    with ctx.db.write() as s:
        study = study_row(s, study_id, for_update=True)
        study.bonus_rule = {"amounts": rule}
        commit(s)
    return {"study_id": study_id, "amounts": rule}


def bonus_rule(ctx: Context, study_id: str) -> dict[str, Any]:
    """The study's bonus rule (empty amounts if none is set)."""
    with ctx.db.read() as s:
        study = study_row(s, study_id)
        return {"study_id": study_id, "amounts": dict((study.bonus_rule or {}).get("amounts") or {})}


def bonus_lines(ctx: Context, study_id: str) -> list[tuple[str, str]]:
    """(Prolific id, amount) for every participant with a Prolific id whose outcome the rule pays for; pilots
    left out. Prolific's bulk bonus takes these as lines "id,amount"."""
    rule = bonus_rule(ctx, study_id)["amounts"]
    if not rule:
        raise InvalidInput(f"study {study_id!r} has no bonus rule; set one first (PUT .../prolific/bonus-rule)")
    with ctx.db.read() as s:
        study_row(s, study_id)
        out = []
        for p in repo.list_participants(s, study_id=study_id, include_pilot=False):
            outcome = outcome_of(p)
            if p.prolific_pid and outcome in rule and Decimal(rule[outcome]) > 0:
                out.append((p.prolific_pid, rule[outcome]))
        return out
