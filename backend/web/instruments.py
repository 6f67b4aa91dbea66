"""The standard HRI questionnaires a study can add to its questionnaire (auth: the experimenter token)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from ..services import instruments
from .deps import Experimenter
from .schemas import error_responses

router = APIRouter(prefix="/api/v1/instruments", tags=["experimenter"], dependencies=[Experimenter],
                   responses=error_responses(401))


@router.get("")
def list_instruments() -> list[dict[str, Any]]:
    """SUS, NASA-TLX (raw), Godspeed and Jian et al.'s trust scale: their items (ready for a study's questionnaire),
    scoring rules (scores.csv) and citations."""
    return instruments.catalogue()
