"""Render docs/scene.png: the scene mid-task through viser in headless Chromium (run as a script)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from conftest import launch_chromium  # noqa: E402

from tableteach.sim.physics import MujocoWorld  # noqa: E402
from tableteach.sim.view import SceneView  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "scene.png"


def main(out: Path = OUT) -> None:
    """Place two objects, freeze the third mid-transport, and screenshot the browser view."""
    world = MujocoWorld(seed=0)
    world.place("dinner_plate")
    world.place("fork")
    start = len(world.recording) - 1
    world.place("small_plate")
    motion = world.recording.since(start)
    view = SceneView(world.model)
    view.set_clickable("dinner_plate", False)
    view.set_clickable("fork", False)
    view.set_caption("The robot is placing the small plate")
    frame = int(0.5 * len(motion))  # halfway: carried over the gap between the tables
    view.set_poses(motion.bodies, motion.poses[frame])
    try:
        with launch_chromium({"width": 1000, "height": 640}) as context:
            page = context.new_page()
            page.goto(view.url)
            page.wait_for_selector("canvas")
            time.sleep(10)  # software WebGL: let it draw a few frames with all nodes
            # Headless Chromium warns about software WebGL; close that toast before the shot.
            for button in page.locator(".mantine-Notification-closeButton").all():
                button.click()
            time.sleep(3)
            page.screenshot(path=str(out))
    finally:
        view.close()
        world.close()
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
