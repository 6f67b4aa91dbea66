"""Every screen a participant meets, at 1366x768 and 390x844, as PNGs in a folder, for a person to look over
(no token, JSON or developer control may show; viser's "Connected" bar and panel included):

    .venv/bin/python tests/browser/screenshot_screens.py [OUT_DIR] [--no-webgl]

Screens: the Prolific ID form, consent, instructions, quiz, the task's introduction, a demonstration (3D view, an
object placed), the early-finish question, a query while the robot moves, its answer screen, the questionnaire
and the done page. Files are named <size>-<nn>-<screen>.png; the folder defaults to a new temporary one.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from conftest import NO_WEBGL_ARGS, LiveServer, launch_chromium  # noqa: E402
from tests.web.conftest import open_study, study_spec  # noqa: E402

SIZES = {"laptop": {"width": 1366, "height": 768}, "phone": {"width": 390, "height": 844}}
QUIZ = [{"id": "who", "text": "Who places the objects on Table B?", "options": ["I do", "The robot"], "correct": 1}]


def walk(server: LiveServer, name: str, viewport: dict[str, int], out: Path, args: list[str]) -> None:
    """Walk one participant through the study, saving a picture of each screen."""
    spec = study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1, n_tests=0, quiz=QUIZ,
                      robot_speed=3.0, completion_url=f"{server.url}/healthz?cc={{code}}")
    study_id = open_study(server.url, spec)
    shots = 0

    def shot(page, screen: str) -> None:
        nonlocal shots
        shots += 1
        time.sleep(0.5)  # transitions settle
        page.screenshot(path=str(out / f"{name}-{shots:02d}-{screen}.png"))

    with launch_chromium(viewport, args) as context:
        page = context.new_page()
        page.goto(f"{server.url}/study/{study_id}/join?STUDY_ID=s1&SESSION_ID=x1")
        page.get_by_label("Your Prolific ID").wait_for()
        shot(page, "prolific-id")
        page.get_by_label("Your Prolific ID").fill(f"screens-{name}")
        page.get_by_role("button", name="Continue").click()
        page.get_by_role("button", name="I agree, continue").wait_for()
        shot(page, "consent")
        page.get_by_role("button", name="I agree, continue").click()
        page.get_by_role("button", name="Start").wait_for()
        shot(page, "instructions")
        page.get_by_role("button", name="Start").click()
        page.wait_for_selector("text=A few questions before you start")
        shot(page, "quiz")
        page.locator('input[name="quiz-who"][value="1"]').check()
        page.get_by_role("button", name="Check my answers").click()
        page.get_by_role("button", name="Begin this task").wait_for()
        shot(page, "task-introduction")
        page.get_by_role("button", name="Begin this task").click()
        page.wait_for_selector("#finish")
        page.locator('button.object[data-object="dinner_plate"]').click()
        page.wait_for_selector("#finish:not([disabled])", timeout=120_000)
        time.sleep(3)  # the view draws the placed plate
        shot(page, "demonstration")
        page.locator("#finish").click()
        page.get_by_role("button", name="Yes, finish now").wait_for()
        shot(page, "finish-early")
        page.get_by_role("button", name="Yes, finish now").click()
        page.get_by_role("button", name="Watch the robot").click()
        page.wait_for_selector("#status.busy", timeout=60_000)
        time.sleep(3)
        shot(page, "query-robot-moving")
        page.wait_for_selector("#acceptable:not([disabled])", timeout=300_000)
        shot(page, "query-answer")
        page.locator("#acceptable").click()
        page.wait_for_selector("text=A few questions")
        shot(page, "questionnaire")
        for radio in ("q-learned", "q-overall"):
            page.locator(f'input[name="{radio}"][value="4"]').check()
        page.get_by_role("button", name="Submit answers").click()
        page.wait_for_selector("#completion-code")
        shot(page, "done")


def main() -> None:
    """Both sizes against one server."""
    names = [a for a in sys.argv[1:] if not a.startswith("--")]
    args = NO_WEBGL_ARGS if "--no-webgl" in sys.argv else []
    out = Path(names[0]) if names else Path(tempfile.mkdtemp(prefix="screens-"))
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as root:
        server = LiveServer(Path(root), robot="mujoco", robot_speed=1.0).start()
        try:
            for name, viewport in SIZES.items():
                walk(server, name, viewport, out, list(args))
        finally:
            server.stop()
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
