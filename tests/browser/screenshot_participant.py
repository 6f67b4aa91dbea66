"""Render docs/participant.png (1366x768) and docs/participant-phone.png (390x844): the participant page while the
robot executes a query, and docs/participant-answer.png (1366x768): the answer screen once the page has shown
it to the end, naming what was placed and what was not (run as a script; a path argument renders only the
laptop picture there, or the phone picture with a second argument `phone`)."""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import httpx  # noqa: E402

from conftest import LiveServer, launch_chromium  # noqa: E402
from joining import join_and_begin  # noqa: E402
from tests.web.conftest import open_study, study_spec  # noqa: E402

DOCS = Path(__file__).resolve().parents[2] / "docs"
OUT = DOCS / "participant.png"
PHONE_OUT = DOCS / "participant-phone.png"
ANSWER_OUT = DOCS / "participant-answer.png"
LAPTOP = {"width": 1366, "height": 768}
PHONE = {"width": 390, "height": 844}


def _caption(server: LiveServer, headers: dict[str, str]) -> str:
    """The robot's caption as any process tells it (from the execution's stored plan and clock)."""
    return httpx.get(f"{server.url}/api/v1/me/robot", headers=headers).json()["caption"]


def main(out: Path = OUT, viewport: dict[str, int] = LAPTOP, answer: Path | None = None) -> None:
    """Two demonstrations through the API, then the page starts the first query and is captured mid-motion."""
    with tempfile.TemporaryDirectory() as root:
        server = LiveServer(Path(root), robot="mujoco", robot_speed=1.0).start()
        try:
            spec = study_spec(["active"], n_practice=0, n_demonstrations=2, n_queries=3, n_tests=1)
            study_id = open_study(server.url, spec)
            with launch_chromium(viewport) as context:
                page = context.new_page()
                token = join_and_begin(page, server.url, study_id, "screenshot")
                headers = {"Authorization": f"Bearer {token}"}
                for demo in (["dinner_plate", "small_plate", "bowl", "knife", "fork"], ["dinner_plate", "bowl"]):
                    for obj in demo:
                        httpx.post(f"{server.url}/api/v1/me/placements", json={"object": obj}, headers=headers)
                    deadline = time.monotonic() + 180  # the robot reports each placement's table first
                    while httpx.post(f"{server.url}/api/v1/me/demonstration/finish", headers=headers,
                                     timeout=60).status_code != 200:
                        if time.monotonic() > deadline:
                            raise TimeoutError("the demonstration could not be finished within 180 s")
                        time.sleep(1.0)
                page.get_by_role("button", name="Watch the robot").click()
                deadline = time.monotonic() + 60
                while "(2 of" not in _caption(server, headers):
                    if time.monotonic() > deadline:
                        raise TimeoutError("the robot did not start its second placement within 60 s")
                    time.sleep(0.1)
                page.wait_for_function("() => document.querySelector('#status')?.textContent.includes('(2 of')")
                time.sleep(1.5)  # mid-transport: the first object set, the second one in the gripper
                page.screenshot(path=str(out))
                if answer is not None:
                    page.wait_for_selector("#acceptable:not([disabled])", timeout=180_000)
                    page.screenshot(path=str(answer))
                    print(f"wrote {answer}")
        finally:
            server.stop()
    print(f"wrote {out}")


if __name__ == "__main__":
    if len(sys.argv) > 1:
        main(Path(sys.argv[1]), PHONE if sys.argv[2:] == ["phone"] else LAPTOP)
    else:
        main(OUT, LAPTOP, ANSWER_OUT)
        main(PHONE_OUT, PHONE)
