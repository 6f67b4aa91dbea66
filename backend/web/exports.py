"""CSV exports, streamed row by row; cells a spreadsheet would run as formulas are escaped."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Iterator
from typing import Any, Literal

from fastapi import APIRouter
from fastapi.responses import StreamingResponse

from .. import services
from .deps import ContextDep, Experimenter
from .schemas import error_responses

# Formula triggers, also in their full-width forms, which some spreadsheets fold to ASCII.
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r", "\n", "\uff1d", "\uff0b", "\uff0d", "\uff20")
router = APIRouter(prefix="/api/v1/studies", tags=["exports"], dependencies=[Experimenter],
                   responses=error_responses(401, 404, 422))


def needs_escape(value: str) -> bool:
    """Whether a spreadsheet could read this text as a formula: it starts with whitespace or a line break
    (spreadsheets trim them) or, after any, with one of FORMULA_STARTS."""
    return bool(value) and (value[0].isspace() or value.lstrip().startswith(FORMULA_STARTS))


def cell(value: Any) -> Any:
    """A CSV cell: text that could start a formula gets a leading apostrophe (OWASP CSV injection)."""
    if isinstance(value, str) and needs_escape(value):
        return "'" + value
    return value


def csv_lines(rows: Iterable[list[Any]]) -> Iterator[str]:
    """Encode rows as CSV text, one chunk per row."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\r\n")
    for row in rows:
        writer.writerow([cell(v) for v in row])
        yield buffer.getvalue()
        buffer.seek(0)
        buffer.truncate(0)


@router.get("/{study_id}/exports/{name}.csv", response_class=StreamingResponse,
            responses={200: {"content": {"text/csv": {}}, "description": "the CSV file"}})
def export(study_id: str, name: Literal["participants", "events", "beliefs", "questionnaire"], ctx: ContextDep
           ) -> StreamingResponse:
    """Download participants.csv, events.csv, beliefs.csv or questionnaire.csv (columns: docs/server.md)."""
    rows = services.export_rows(ctx, study_id, name)
    filename = f"{study_id}-{name}.csv"
    return StreamingResponse(csv_lines(rows), media_type="text/csv; charset=utf-8",
                             headers={"Content-Disposition": f'attachment; filename="{filename}"'})
