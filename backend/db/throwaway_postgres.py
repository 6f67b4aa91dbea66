"""A throwaway PostgreSQL cluster for tests and benchmarks: Debian's server binaries (package `postgresql`),
a fresh data folder, trust authentication on 127.0.0.1, removed again on stop. Not for production."""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def postgres_bin() -> Path | None:
    """The newest installed PostgreSQL server's bin folder, or None if there is none."""
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(found[-1]).parent if found else None


def available() -> bool:
    """Whether the server binaries and the psycopg driver are installed."""
    import importlib.util

    return postgres_bin() is not None and importlib.util.find_spec("psycopg") is not None


def _as_server_user(args: list[str]) -> list[str]:
    """PostgreSQL refuses to run as root: use the package's postgres user then."""
    if os.geteuid() == 0:
        return ["runuser", "-u", "postgres", "--", *args]
    return args


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def throwaway_postgres(max_connections: int = 100) -> Iterator[str]:
    """Start a fresh cluster and yield its SQLAlchemy URL; stop and delete it on exit.

    RuntimeError if Debian's postgresql package is missing (expected /usr/lib/postgresql/*/bin/initdb)."""
    bin_dir = postgres_bin()
    if bin_dir is None:
        raise RuntimeError("no PostgreSQL server binaries: expected Debian's postgresql package "
                           "(/usr/lib/postgresql/*/bin/initdb)")
    # Not under a private temp tree: the postgres user cannot traverse root's private folders.
    folder = Path(tempfile.mkdtemp(prefix="tableteach-pg-"))
    if os.geteuid() == 0:
        shutil.chown(folder, user="postgres")
    data, port = folder / "data", _free_port()
    try:
        subprocess.run(_as_server_user([str(bin_dir / "initdb"), "-D", str(data), "-A", "trust", "-U", "tableteach"]),
                       check=True, capture_output=True)
        options = f"-p {port} -k {folder} -c listen_addresses=127.0.0.1 -c max_connections={max_connections}"
        subprocess.run(_as_server_user([str(bin_dir / "pg_ctl"), "-D", str(data), "-o", options, "-l",
                                        str(folder / "server.log"), "-w", "start"]), check=True, capture_output=True)
        yield f"postgresql+psycopg://tableteach@127.0.0.1:{port}/postgres"
    finally:
        if (data / "postmaster.pid").exists():
            subprocess.run(_as_server_user([str(bin_dir / "pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop"]),
                           capture_output=True)
        shutil.rmtree(folder, ignore_errors=True)
