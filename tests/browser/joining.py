"""Joining a study in the browser as a new participant, up to the first task's screen."""

from __future__ import annotations

from typing import Any


def join_and_begin(page: Any, url: str, study_id: str, pid: str, *, query: str = "") -> str:
    """Open the study link, consent, read the instructions and begin the first task; the participant's token."""
    page.goto(f"{url}/study/{study_id}/join?PROLIFIC_PID={pid}{query}")
    page.get_by_role("button", name="I agree, continue").click()
    page.get_by_role("button", name="Start").click()
    page.get_by_role("button", name="Begin this task").click()
    return token_of(page)


def token_of(page: Any) -> str:
    """The participant's token, the last part of the page's address once they have joined."""
    return str(page.url.rstrip("/").rsplit("/", 1)[-1])
