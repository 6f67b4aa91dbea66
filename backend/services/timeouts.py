"""The periodic time-out sweep (the runtime runs it): participants idle past their study's limit are screened out
by the runtime, never by whoever happens to read their state."""

from __future__ import annotations

import logging

from ..db import repository as repo
from .context import Context
from .lifecycle import expire_timeouts

log = logging.getLogger(__name__)


def sweep_timeouts(ctx: Context) -> int:
    """Screen out everyone idle past their study's time-out in every study; how many. Never raises."""
    try:
        with ctx.db.read() as s:
            studies = [study.id for study in repo.list_studies(s) if study.timeout_minutes]
        return sum(expire_timeouts(ctx, study_id) for study_id in studies)
    except Exception:  # noqa: BLE001 - the next sweep tries again
        log.warning("the time-out sweep failed; it runs again shortly", exc_info=True)
        return 0
