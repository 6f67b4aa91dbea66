"""Serving files of frontend/ by an explicit allow-list, so nothing else there (or above it) can be reached by name."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from fastapi.responses import FileResponse

from ..errors import NotFound

FRONTEND = Path(__file__).resolve().parents[2] / "frontend"


def allowed_file(name: str, allowed: Mapping[str, str], *, what: str, headers: Mapping[str, str]) -> FileResponse:
    """A listed frontend file with its media type; NotFound naming the listed files otherwise."""
    if name not in allowed:
        raise NotFound(f"no {what} named {name!r}; expected one of {', '.join(sorted(allowed))}")
    return FileResponse(FRONTEND / name, media_type=allowed[name], headers=dict(headers))
