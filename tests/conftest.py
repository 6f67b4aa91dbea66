"""Shared test configuration: hypothesis profiles, paths, and the guard that keeps tests out of the checkout's var/.

The server's default database and data folder are under var/ (the README's `bash scripts/serve.sh` fills them).
Tests must neither read nor write there: the defaults are pointed at a scratch folder for the whole run
(TABLETEACH_DATABASE_URL / TABLETEACH_DATA_DIR, inherited by servers the tests start), and the run fails if
anything under var/ was created, changed or deleted."""

import os
import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile("ci", max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("ci" if os.environ.get("CI") else "dev")

REPO = Path(__file__).resolve().parents[1]
AUTHORS_DATA = REPO.parent / "shared" / "data" / "authors"
CHECKOUT_VAR = REPO / "var"


def var_snapshot(folder: Path = CHECKOUT_VAR) -> dict[str, tuple[int, int]] | None:
    """Every file under the folder with its size and modification time (None if there is no such folder)."""
    if not folder.exists():
        return None
    out = {}
    for path in folder.rglob("*"):
        try:
            if path.is_file():
                stat = path.stat()
                out[path.relative_to(folder).as_posix()] = (stat.st_size, stat.st_mtime_ns)
        except FileNotFoundError:
            continue  # a server outside the tests removed it meanwhile (e.g. a WAL file)
    return out


def pytest_configure(config: pytest.Config) -> None:
    """Before anything is collected: point the settings' defaults at a scratch folder and note var/ as it is."""
    scratch = Path(tempfile.mkdtemp(prefix="tableteach-tests-"))
    config.stash[_SCRATCH] = scratch
    config.stash[_VAR_BEFORE] = var_snapshot()
    os.environ["TABLETEACH_DATA_DIR"] = str(scratch / "data")
    os.environ["TABLETEACH_DATABASE_URL"] = f"sqlite:///{scratch / 'default.db'}"


def pytest_unconfigure(config: pytest.Config) -> None:
    """Remove the scratch folder."""
    scratch = config.stash.get(_SCRATCH, None)
    if scratch is not None:
        shutil.rmtree(scratch, ignore_errors=True)


_SCRATCH = pytest.StashKey[Path]()
_VAR_BEFORE = pytest.StashKey["dict[str, tuple[int, int]] | None"]()


@pytest.fixture(scope="session", autouse=True)
def checkout_var_untouched(request: pytest.FixtureRequest) -> object:
    """Fail the run if any test created, changed or deleted a file under the checkout's var/."""
    yield
    before, after = request.config.stash[_VAR_BEFORE], var_snapshot()
    if before != after:
        before, after = before or {}, after or {}
        changed = sorted(k for k in before.keys() | after.keys() if before.get(k) != after.get(k))
        pytest.fail(f"the tests changed the checkout's var/ (tests must use tmp_path): {', '.join(changed[:10])}")
