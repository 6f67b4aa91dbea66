"""The participant page through a crash: the server is killed with -9 during a demonstration (one placement
acknowledged and maybe not yet reported by the robot) and started again; the page recovers by itself, and its
3D view shows the same objects in the same places as before the crash (as its panel says)."""

from __future__ import annotations

from pathlib import Path

import httpx
import numpy as np
import pytest

from tests.web.conftest import ServerProcess, open_study, study_spec

from joining import join_and_begin
from view_pixels import settled_view

pytestmark = pytest.mark.browser
WAIT_MS = 120_000
PLACED = "name => document.querySelector('.placed')?.textContent.includes(name)"  # a function: the page's CSP


class RestartableServer(ServerProcess):
    """A server process that comes back on the same port after kill() (the page's address stays valid)."""

    def start(self) -> "RestartableServer":
        port = self.port
        super().start() if not port else self._start_on(port)
        return self

    def _start_on(self, port: int) -> None:
        from tests.web import conftest

        chosen = conftest.free_port
        conftest.free_port = lambda: port  # type: ignore[assignment]
        try:
            super().start()
        finally:
            conftest.free_port = chosen


def test_the_page_recovers_from_a_kill_and_its_view_agrees_with_its_panel(browser_page, tmp_path: Path) -> None:
    page = browser_page
    server = RestartableServer(tmp_path / "crash.db", TABLETEACH_ROBOT="mujoco", TABLETEACH_ROBOT_SPEED="4",
                               TABLETEACH_JOINS_PER_ADDRESS="1000")
    from tableteach.db.migrate import upgrade_head

    upgrade_head(server.database_url)
    server.start()
    try:
        study_id = open_study(server.url, study_spec(["active"], n_practice=0, n_demonstrations=2, n_queries=1,
                                                     n_tests=0))
        token = join_and_begin(page, server.url, study_id, "crash-1", query="&STUDY_ID=s1&SESSION_ID=x1")
        page.wait_for_selector("#viewer-frame", timeout=WAIT_MS)
        empty = settled_view(page)

        page.locator('button.object[data-object="dinner_plate"]').click()
        page.wait_for_function(PLACED, arg="dinner plate", timeout=WAIT_MS)
        page.wait_for_selector("#finish:not([disabled])", timeout=WAIT_MS)  # the robot has placed it
        page.locator('button.object[data-object="bowl"]').click()  # acknowledged, then the crash at once
        page.wait_for_function(PLACED, arg="bowl", timeout=WAIT_MS)
        server.kill()
        server.start()

        # Nothing but the page's own reads and event stream from here on.
        page.wait_for_selector("#finish:not([disabled])", timeout=WAIT_MS)
        placed = page.locator(".placed").inner_text()
        assert "dinner plate" in placed and "bowl" in placed
        state = httpx.get(f"{server.url}/api/v1/me", headers={"Authorization": f"Bearer {token}"}, timeout=60).json()
        assert state["demonstration"]["placed"] == ["dinner_plate", "bowl"] and state["demonstration"]["settled"]
        after = settled_view(page)

        # The same scene rebuilt: a fresh table with the two objects placed, as a view of the stored placements.
        page.reload()
        page.wait_for_selector("#finish:not([disabled])", timeout=WAIT_MS)
        reloaded = settled_view(page)
        assert after.shape == reloaded.shape == empty.shape
        same = np.abs(after - reloaded).mean()
        moved = np.abs(empty - reloaded).mean()
        # The recovered view is nearer the fresh view of the stored placements than the empty table is (a view that
        # lost the table, the defect, would look like the empty table).
        assert same < 0.8 * moved, (same, moved)
    finally:
        server.kill()
