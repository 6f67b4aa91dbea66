"""Render docs/participant-objects.png (1366x768) and docs/participant-objects-phone.png (390x844): the participant
page of a study with its own objects (the lunch box study of tests/study_objects.py) during a demonstration, two
objects placed by the MuJoCo robot, in the 3D view; and docs/goal-objects.png, its goal picture (run as a script)."""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import httpx  # noqa: E402

from conftest import LiveServer, launch_chromium  # noqa: E402
from tests.study_objects import lunch_study  # noqa: E402
from tests.web.conftest import open_study  # noqa: E402

DOCS = Path(__file__).resolve().parents[2] / "docs"
LAPTOP = {"width": 1366, "height": 768}
PHONE = {"width": 390, "height": 844}
SETTLE_SECONDS = 20.0  # software WebGL draws the 3D view a few frames a second: let it draw the table


def _settled(server: LiveServer, headers: dict[str, str], placed: int) -> bool:
    demonstration = httpx.get(f"{server.url}/api/v1/me", headers=headers).json()["demonstration"]
    return len(demonstration["placed"]) == placed and demonstration["settled"]


def main() -> None:
    """Two placements through the API, then each viewport's page is captured with the robot idle."""
    with tempfile.TemporaryDirectory() as root:
        server = LiveServer(Path(root), robot="mujoco", robot_speed=8.0).start()
        try:
            study_id = open_study(server.url, lunch_study(n_demonstrations=2))
            for viewport, name in ((LAPTOP, "participant-objects.png"), (PHONE, "participant-objects-phone.png")):
                with launch_chromium(viewport) as context:
                    page = context.new_page()
                    page.add_init_script("localStorage.setItem('tableteach-view', '3d')")
                    page.goto(f"{server.url}/study/{study_id}/join?PROLIFIC_PID=shot-{viewport['width']}")
                    page.get_by_role("button", name="I agree, continue").click()
                    page.get_by_role("button", name="Start").click()
                    if name == "participant-objects.png":
                        page.locator("figure.goal img").screenshot(path=str(DOCS / "goal-objects.png"))
                    page.get_by_role("button", name="Begin this task").click()
                    token = page.url.rstrip("/").rsplit("/", 1)[-1]
                    headers = {"Authorization": f"Bearer {token}"}
                    for count, obj in enumerate(("lunch_box", "spoon"), start=1):
                        httpx.post(f"{server.url}/api/v1/me/placements", json={"object": obj}, headers=headers)
                        deadline = time.monotonic() + 120
                        while not _settled(server, headers, count):
                            if time.monotonic() > deadline:
                                raise TimeoutError(f"the robot did not report placing the {obj} within 120 s")
                            time.sleep(0.2)
                    page.wait_for_selector("#finish:not([disabled])", timeout=120_000)
                    time.sleep(SETTLE_SECONDS)
                    page.screenshot(path=str(DOCS / name), full_page=viewport is PHONE)
                    print(f"wrote {DOCS / name}")
        finally:
            server.stop()


if __name__ == "__main__":
    main()
