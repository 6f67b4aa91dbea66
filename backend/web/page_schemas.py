"""Request models of the participant page's study settings (services/page_settings.py), apart from schemas.py."""

from __future__ import annotations

from typing import Literal

from ..services.page_settings import ConsentFormIn as _ConsentFormIn
from pydantic import BaseModel, ConfigDict, Field


ConsentFormIn = _ConsentFormIn  # the study definition's model (services/page_settings.py)


class SignalIn(BaseModel):
    """One signal of the participant page: attention telemetry, or presence before an idle time-out."""

    model_config = ConfigDict(extra="forbid", strict=True)

    kind: Literal["tab_hidden", "window_blur", "paste", "still_here"]
    field: str | None = Field(None, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$",
                              description="paste: the questionnaire item pasted into")
