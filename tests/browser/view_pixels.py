"""The participant page's 3D view as pixels: a screenshot of the embedded viewer frame, and one once it is still."""

from __future__ import annotations

import io
import time

import numpy as np
from PIL import Image

WAIT_MS = 120_000


def view_pixels(page) -> np.ndarray:
    """The 3D view as grey pixels (the embedded viewer frame only)."""
    frame = page.locator("#viewer-frame")
    frame.wait_for(state="visible", timeout=WAIT_MS)
    frame.scroll_into_view_if_needed(timeout=WAIT_MS)
    page.wait_for_function("() => { const r = document.querySelector('#viewer-frame')?.getBoundingClientRect();"
                           " return r && r.width > 10 && r.height > 10; }", timeout=WAIT_MS)
    box = frame.bounding_box()
    assert box is not None, "the page shows no 3D view"
    shot = page.screenshot(clip=box, animations="disabled", timeout=WAIT_MS)
    return np.asarray(Image.open(io.BytesIO(shot)).convert("L"), dtype=float)


def settled_view(page, seconds: float = 4.0) -> np.ndarray:
    """The view once it has stopped changing (software WebGL draws slowly)."""
    last = view_pixels(page)
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        time.sleep(seconds)
        now = view_pixels(page)
        if now.shape == last.shape and np.abs(now - last).mean() < 0.5:
            return now
        last = now
    return last
