"""Clicking scene objects from Playwright: wait for the browser's camera, project a 3D point to a pixel."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import viser.transforms as vtf


def wait_for_camera(server: Any, timeout: float = 60.0) -> Any:
    """The camera of the first browser connected to a ViserServer, or of the clients a callable lists (once it has
    reported one)."""
    clients = server if callable(server) else (lambda: list(server.get_clients().values()))
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for client in clients():
            try:
                client.camera.fov  # noqa: B018 - raises until the browser has reported its camera
                return client.camera
            except AssertionError:
                pass
        time.sleep(0.1)
    raise TimeoutError(f"no browser camera reported within {timeout} s: expected the 3D view to connect")


def project(camera: Any, point: np.ndarray, width: float, height: float) -> tuple[float, float]:
    """Pixel of a world point in the client's canvas (viser cameras follow OpenCV: +z ahead, +y down)."""
    rotation = vtf.SO3(np.asarray(camera.wxyz)).as_matrix()
    local = rotation.T @ (point - np.asarray(camera.position))
    assert local[2] > 0, "point is behind the camera"
    focal = (height / 2) / np.tan(camera.fov / 2)
    return width / 2 + focal * local[0] / local[2], height / 2 + focal * local[1] / local[2]
