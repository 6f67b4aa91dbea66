"""Fixtures for the server tests: a real server process on a free port, and an in-process app."""

from __future__ import annotations

from contextlib import contextmanager

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tableteach.client import ExperimenterClient

EXPERIMENTER_TOKEN = "test-experimenter-token-0123456789"
# Tests join many participants from one address; the per-address join limit has its own tests
# (test_abuse_limits.py), which set it low.
JOINS_UNLIMITED = {"TABLETEACH_JOINS_PER_ADDRESS": "100000"}
START_SECONDS = 180.0  # a server's start-up on a loaded machine (normally 2-3 s; over 60 s at load 23)
QUESTIONNAIRE = [
    {"id": "learned", "text": "The robot learned the task.", "kind": "likert5"},
    {"id": "overall", "text": "Overall rating", "kind": "rating10"},
    {"id": "comments", "text": "Comments", "kind": "text", "required": False},
]


def free_port() -> int:
    """A TCP port that was free a moment ago on 127.0.0.1."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServerProcess:
    """`tableteach serve` in a subprocess (a temp SQLite file unless a URL is given); kill() is a crash."""

    def __init__(self, db_path: Path, database_url: str | None = None, **env: str) -> None:
        self.db_path = db_path
        self.database_url = database_url or f"sqlite:///{db_path}"
        self.env = env
        self.proc: subprocess.Popen[bytes] | None = None
        self.port = 0

    @property
    def url(self) -> str:
        """Base URL."""
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> "ServerProcess":
        """Start and wait until /healthz answers."""
        self.port = free_port()
        # The trace robot unless a test asks for MuJoCo (TABLETEACH_ROBOT=mujoco): these tests are about the server.
        env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": EXPERIMENTER_TOKEN, "TABLETEACH_ROBOT": "trace",
               "TABLETEACH_DATA_DIR": str(self.db_path.parent / "data"), **JOINS_UNLIMITED, **self.env}
        env.pop("TABLETEACH_DEV_MODE", None)
        log = open(self.db_path.with_suffix(f".{self.port}.log"), "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tableteach.cli", "serve", "--migrate", "--port", str(self.port),
             "--database-url", self.database_url],
            env=env, stdout=log, stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + START_SECONDS
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited with {self.proc.returncode}: "
                                   f"{self.db_path.with_suffix(f'.{self.port}.log').read_text()}")
            try:
                if httpx.get(f"{self.url}/healthz", timeout=5).status_code == 200:
                    return self
            except httpx.TransportError:
                time.sleep(0.1)
        raise RuntimeError(f"server did not answer /healthz within {START_SECONDS:.0f} s")

    def kill(self) -> None:
        """SIGKILL: nothing gets a chance to flush."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=10)

    def stop(self) -> None:
        """SIGTERM, then SIGKILL if needed."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.kill()


@pytest.fixture
def server_factory(tmp_path: Path) -> Iterator[Any]:
    """Start servers on one temp database (several in turn, for restarts); all are stopped at the end."""
    started: list[ServerProcess] = []
    db_path = tmp_path / "study.db"

    def start(**env: str) -> ServerProcess:
        server = ServerProcess(db_path, **env).start()
        started.append(server)
        return server

    yield start
    for server in started:
        server.stop()


@pytest.fixture(scope="module")
def shared_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    """One server for a whole test module."""
    server = ServerProcess(tmp_path_factory.mktemp("server") / "study.db").start()
    yield server
    server.stop()


def study_spec(conditions: list[str], tasks: list[dict[str, Any]] | None = None, **extra: Any) -> dict[str, Any]:
    """A small study definition."""
    return {"name": f"test {'/'.join(conditions)}", "tasks": tasks or [{"key": "task1"}], "conditions": conditions,
            "questionnaire": QUESTIONNAIRE, **extra}


def open_study(url: str, spec: dict[str, Any]) -> str:
    """Create and open a study; its id."""
    exp = ExperimenterClient(url, token=EXPERIMENTER_TOKEN)
    try:
        study = exp.create_study(spec)
        exp.open_study(study["id"])
        return study["id"]
    finally:
        exp.close()


@contextmanager
def in_process_app(tmp_path: Path, robot: Any = None) -> Iterator[Any]:
    """An in-process app (TestClient) on a migrated temp SQLite file, with the given robot (default: the trace
    robot); .ctx is its services context."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Starlette 1.10 deprecates httpx inside TestClient; it still works
        from starlette.testclient import TestClient

    from tableteach.config import Settings
    from tableteach.db.migrate import upgrade_head
    from tableteach.services import Context
    from tableteach.web.app import create_app

    settings = Settings(database_url=f"sqlite:///{tmp_path / 'app.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                        robot="trace", data_dir=tmp_path / "data", joins_per_address=100_000)
    upgrade_head(settings.database_url)
    from tableteach.web.robots import make_recording_store

    context = None if robot is None else Context.from_settings(settings, robot,
                                                               lambda db: make_recording_store(settings, db))
    app = create_app(settings, context=context)
    with TestClient(app) as client:
        client.ctx = app.state.context  # type: ignore[attr-defined]
        yield client


@pytest.fixture
def app_client(tmp_path: Path) -> Iterator[Any]:
    """An in-process app on a temp SQLite file with the trace robot (see in_process_app)."""
    with in_process_app(tmp_path) as client:
        yield client
