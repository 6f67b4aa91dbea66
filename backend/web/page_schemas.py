"""Request models of the participant page's study settings (services/page_settings.py), apart from schemas.py."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


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


class SignalIn(BaseModel):
    """One signal of the participant page: attention telemetry, or presence before an idle time-out."""

    model_config = ConfigDict(extra="forbid", strict=True)

    kind: Literal["tab_hidden", "window_blur", "paste", "still_here"]
    field: str | None = Field(None, max_length=64, pattern=r"^[A-Za-z0-9_\-]+$",
                              description="paste: the questionnaire item pasted into")
