"""The periodic sweeps (the runtime runs them): participants idle past their study's limit are screened out by the
runtime, never by whoever happens to read their state; a host's cached recordings of participants erased on another
host are removed."""

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


def forget_erased_copies(ctx: Context) -> int:
    """Remove this host's cached copies of recordings of participants erased or withdrawn on any host (the store
    every host reaches lost them already); how many folders. Never raises."""
    try:
        cached = ctx.store.cached_uids()
        if not cached:
            return 0
        with ctx.db.read() as s:
            gone = repo.uids_without_data(s, uids=cached)
        return ctx.store.forget_cached(gone) if gone else 0
    except Exception:  # noqa: BLE001 - the next sweep tries again
        log.warning("could not remove cached recordings of erased participants now; the next sweep does",
                    exc_info=True)
        return 0
