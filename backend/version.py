"""The installed tableteach version (written into every event, /healthz and backups); standard library only."""

from __future__ import annotations

from functools import lru_cache


@lru_cache(maxsize=1)
def app_version() -> str:
    """The installed tableteach version, or "unknown" when run from a checkout that is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tableteach")
    except PackageNotFoundError:
        return "unknown"
