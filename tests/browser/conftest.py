"""Shared fixtures for browser tests: Debian's Chromium driven by Playwright, never downloaded."""

from __future__ import annotations

import atexit
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
VIEWPORT = {"width": 640, "height": 400}
TIMEOUT_MS = 120_000  # software WebGL renders a few frames per second, far fewer on a loaded machine


NO_WEBGL_ARGS = ["--disable-3d-apis"]  # a browser without WebGL (the participant page then shows its 2D view)


_DRIVER: list[object] = []


def playwright_driver() -> Any:
    """This process's one Playwright driver, started on first use: Playwright's sync API refuses a second one
    while the first runs (the session's shared browser), so every browser of the process comes from this one."""
    if not _DRIVER:
        from playwright.sync_api import sync_playwright

        driver = sync_playwright().start()
        atexit.register(driver.stop)
        _DRIVER.append(driver)
    return _DRIVER[0]


@contextmanager
def launch_chromium(viewport: dict[str, int] = VIEWPORT, extra_args: list[str] | None = None) -> Iterator[object]:
    """A Playwright BrowserContext on /usr/bin/chromium with a fresh user-data dir (and extra_args for Chromium)."""
    pw = playwright_driver()
    with tempfile.TemporaryDirectory(prefix="chromium-profile-") as profile:
        context = pw.chromium.launch_persistent_context(
            profile,
            executable_path=str(CHROMIUM),
            args=CHROMIUM_ARGS + list(extra_args or []),
            headless=True,
            viewport=viewport,
        )
        context.set_default_timeout(TIMEOUT_MS)
        try:
            yield context
        finally:
            context.close()


@pytest.fixture(scope="session")
def chromium_browser() -> Iterator[object]:
    """Session-wide Chromium context; skipped without /usr/bin/chromium unless CI=true (then it fails)."""
    if not CHROMIUM.exists():
        message = f"{CHROMIUM} not found: install Debian's chromium package (apt-get install -y chromium)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)
    with launch_chromium() as context:
        yield context


# As a participant who chose the 3D view: on this loaded machine software WebGL stalls the page, and the page would
# rightly switch to its 2D view (participant-view-mode.js), under tests that click or compare the 3D view.
CHOSE_3D_VIEW = ("try { if (!localStorage.getItem('tableteach-view')) localStorage.setItem('tableteach-view', '3d'); }"
                 " catch (e) {}")


@pytest.fixture
def browser_page(chromium_browser: object) -> Iterator[object]:
    """A fresh page in the shared Chromium context, as a participant who chose the 3D view; closed after the test."""
    page = chromium_browser.new_page()  # type: ignore[attr-defined]
    page.add_init_script(CHOSE_3D_VIEW)
    try:
        yield page
    finally:
        page.close()


@pytest.fixture
def default_view_page(chromium_browser: object) -> Iterator[object]:
    """A fresh page in the shared Chromium context with no view chosen (the page picks 3D or 2D itself)."""
    page = chromium_browser.new_page()  # type: ignore[attr-defined]
    try:
        yield page
    finally:
        page.close()


class LiveServer:
    """The study app served by uvicorn in a thread of the test process, so tests can look at its robot."""

    def __init__(self, root: Path, **settings: object) -> None:
        import threading

        import uvicorn

        from tableteach.config import Settings
        from tableteach.db.migrate import upgrade_head
        from tableteach.web.app import create_app
        from tests.web.conftest import EXPERIMENTER_TOKEN, free_port

        self.settings = Settings(database_url=f"sqlite:///{root / 'study.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                                 data_dir=root / "data", port=free_port(), **settings)
        upgrade_head(self.settings.database_url)
        self.app = create_app(self.settings)
        self.ctx = self.app.state.context
        config = uvicorn.Config(self.app, host="127.0.0.1", port=self.settings.port, log_level="warning",
                                timeout_graceful_shutdown=2)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, name="live-server", daemon=True)

    @property
    def url(self) -> str:
        """Base URL."""
        return f"http://127.0.0.1:{self.settings.port}"

    def start(self) -> "LiveServer":
        """Serve and wait until it listens."""
        import time

        from tests.web.conftest import START_SECONDS

        self.thread.start()
        deadline = time.monotonic() + START_SECONDS
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError(f"the live server did not start within {START_SECONDS:.0f} s")
            time.sleep(0.05)
        return self

    def stop(self) -> None:
        """Ask uvicorn to exit (the app's lifespan stops the robot's viser servers) and wait."""
        self.server.should_exit = True
        self.thread.join(timeout=15)


@pytest.fixture
def mujoco_server(tmp_path: Path) -> Iterator[LiveServer]:
    """The app with the MuJoCo robot replaying motions 8x faster than real time, on a temp database."""
    server = LiveServer(tmp_path, robot="mujoco", robot_speed=8.0).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def slow_mujoco_server(tmp_path: Path) -> Iterator[LiveServer]:
    """The app with the MuJoCo robot at 2x real time: long enough to act while the robot still moves."""
    server = LiveServer(tmp_path, robot="mujoco", robot_speed=2.0).start()
    try:
        yield server
    finally:
        server.stop()
