"""CSV exports, streamed row by row; cells a spreadsheet would run as formulas are escaped."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Iterator
import zipfile
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query
from fastapi.responses import Response, StreamingResponse

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
    """A CSV cell: booleans as true/false; text a spreadsheet could read as a formula gets a leading apostrophe
    (OWASP CSV injection)."""
    if isinstance(value, bool):
        return "true" if value else "false"
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


IncludePilot = Annotated[bool, Query(description="also pilot participants (left out by default)")]


def _attachment(filename: str) -> dict[str, str]:
    return {"Content-Disposition": f'attachment; filename="{filename}"'}


@router.get("/{study_id}/exports/exports.zip", response_class=Response,
            responses={200: {"content": {"application/zip": {"schema": {"type": "string", "format": "binary"}}},
                             "description": "every CSV, codebook.csv and study.json"}})
def export_zip(study_id: str, ctx: ContextDep, include_pilot: IncludePilot = False) -> Response:
    """Download exports.zip: every CSV below, codebook.csv and the study definition (study.json)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, content in services.export_files(ctx, study_id, include_pilot=include_pilot):
            text = content if isinstance(content, str) else "".join(csv_lines(content))
            archive.writestr(name, text)
    return Response(buffer.getvalue(), media_type="application/zip",
                    headers=_attachment(f"{study_id}-exports.zip"))


@router.get("/{study_id}/exports/{name}.csv", response_class=StreamingResponse,
            responses={200: {"content": {"text/csv": {"schema": {"type": "string", "format": "binary"}}},
                             "description": "the CSV file"}})
def export(study_id: str,
           name: Literal["participants", "events", "steps", "beliefs", "questionnaire", "scores", "codebook"],
           ctx: ContextDep, include_pilot: IncludePilot = False) -> StreamingResponse:
    """Download participants, events, steps, beliefs, questionnaire, scores (standard questionnaires) or codebook
    .csv (columns: codebook.csv)."""
    if name == "codebook":
        rows = services.codebook_rows(ctx, study_id)
    else:
        rows = services.export_rows(ctx, study_id, name, include_pilot=include_pilot)
    return StreamingResponse(csv_lines(rows), media_type="text/csv; charset=utf-8",
                             headers=_attachment(f"{study_id}-{name}.csv"))
