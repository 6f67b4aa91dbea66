"""Errors raised by services and mapped to HTTP in one place (web/errors.py)."""

from __future__ import annotations

from typing import Any


class TableTeachError(Exception):
    """Base class: a message that says what was wrong and what was expected."""

    def __init__(self, message: str, *, state: Any = None) -> None:
        super().__init__(message)
        self.message = message
        self.state = state


class NotFound(TableTeachError):
    """The named study, participant or resource does not exist (HTTP 404)."""


class Conflict(TableTeachError):
    """The request clashes with the current state, e.g. out of order or a repeated id (HTTP 409)."""


class ResumeRefused(Conflict):
    """An external id that has joined before, without its session id or browser (HTTP 409, nothing about them)."""


class StudyFull(Conflict):
    """Every place of the study is taken (finished plus under way, as Prolific counts them) (HTTP 409)."""


class InvalidInput(TableTeachError):
    """The request is well-formed but its values are not acceptable (HTTP 422)."""


class InvalidFields(InvalidInput):
    """Several fields are unacceptable at once: errors lists each field's path and a plain message (HTTP 422)."""

    def __init__(self, errors: list[dict[str, str]]) -> None:
        super().__init__("; ".join(f"{e['field']}: {e['message']}" for e in errors))
        self.errors = errors


class NotAuthenticated(TableTeachError):
    """Missing or wrong credentials (HTTP 401)."""


class Forbidden(TableTeachError):
    """Known credentials whose role does not allow this request (HTTP 403)."""


class TryLater(TableTeachError):
    """Not now: too many wrong attempts (HTTP 429) or the database is busy or missing (HTTP 503)."""

    def __init__(self, message: str, *, retry_after: int, status: int = 503, state: Any = None) -> None:
        super().__init__(message, state=state)
        self.retry_after = retry_after
        self.status = status
