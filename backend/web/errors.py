"""The one place where errors become HTTP answers: {"detail": message, "state": participant state or null}."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException as StarletteHTTPException

from ..core.session import ProtocolError
from ..errors import (Conflict, Forbidden, InvalidInput, NotAuthenticated, NotFound, ResumeRefused, StudyFull,
                      TableTeachError, TryLater)
from ..services.plain_words import field_errors
from ..services.study_definition import PATTERN_HINTS
from .pages import error_page, is_page

log = logging.getLogger(__name__)

STATUS = {NotFound: 404, Conflict: 409, InvalidInput: 422, NotAuthenticated: 401, Forbidden: 403}


def _answer(status: int, detail: str, state: object = None, headers: dict[str, str] | None = None,
            errors: list[dict[str, str]] | None = None) -> JSONResponse:
    body: dict[str, object] = {"detail": detail, "state": state}
    if errors is not None:
        body["errors"] = errors
    return JSONResponse(body, status_code=status, headers=headers)


def _field_errors(exc: RequestValidationError) -> list[dict[str, str]]:
    return field_errors(exc.errors(), PATTERN_HINTS)


def _validation_message(errors: list[dict[str, str]]) -> str:
    return "; ".join(f"{e['field']}: {e['message']}" for e in errors[:5]) or "invalid request"


def _for(request: Request, answer: JSONResponse, *, resume_refused: bool = False,
         study_full: bool = False) -> Response:
    """Participant-facing pages (/study/..., /p/...) answer a plain-words HTML page instead of JSON."""
    if not is_page(request.url.path):
        return answer
    own = {k: v for k, v in answer.headers.items() if k not in ("content-type", "content-length")}
    return error_page(answer.status_code, own, resume_refused=resume_refused, study_full=study_full)


def install(app: FastAPI) -> None:
    """Register the exception handlers."""

    @app.exception_handler(TableTeachError)
    async def _service_error(request: Request, exc: TableTeachError) -> Response:
        if isinstance(exc, TryLater):
            return _for(request, _answer(exc.status, exc.message, exc.state, {"Retry-After": str(exc.retry_after)}))
        status = next((code for cls, code in STATUS.items() if isinstance(exc, cls)), 400)
        headers = {"WWW-Authenticate": "Bearer"} if status == 401 else None
        return _for(request, _answer(status, exc.message, exc.state, headers, getattr(exc, "errors", None)),
                    resume_refused=isinstance(exc, ResumeRefused), study_full=isinstance(exc, StudyFull))

    @app.exception_handler(ProtocolError)
    async def _protocol_error(request: Request, exc: ProtocolError) -> Response:
        return _for(request, _answer(409, str(exc)))

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> Response:
        errors = _field_errors(exc)
        return _for(request, _answer(422, _validation_message(errors), errors=errors))

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> Response:
        return _for(request, _answer(exc.status_code, str(exc.detail), None, getattr(exc, "headers", None)))

    @app.exception_handler(OverflowError)
    async def _too_large(request: Request, exc: OverflowError) -> Response:
        log.warning("number out of range on %s %s: %s", request.method, request.url.path, exc)
        return _for(request, _answer(422, "a number in the request is too large: expected ids and counts below 2^31"))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> Response:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return _for(request, _answer(500, "internal error; it has been logged"))
