"""Render docs/participant-2d.png (1366x768) and docs/participant-2d-phone.png (390x844): the participant page's 2D
view in a browser without WebGL while the robot executes a query (run as a script)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import screenshot_participant as shots  # noqa: E402
from conftest import NO_WEBGL_ARGS, launch_chromium  # noqa: E402

DOCS = Path(__file__).resolve().parents[2] / "docs"


def main() -> None:
    """The participant page's screenshots (screenshot_participant.main), in a Chromium without WebGL."""
    shots.launch_chromium = lambda viewport: launch_chromium(viewport, NO_WEBGL_ARGS)
    shots.main(DOCS / "participant-2d.png", shots.LAPTOP)
    shots.main(DOCS / "participant-2d-phone.png", shots.PHONE)


if __name__ == "__main__":
    main()
