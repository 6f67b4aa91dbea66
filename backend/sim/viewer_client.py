"""Where viser's browser client lives: one self-contained index.html inside the installed viser wheel."""

from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path


@lru_cache(maxsize=1)
def client_html() -> bytes:
    """The bytes of viser's built client page (found without importing viser)."""
    spec = importlib.util.find_spec("viser")
    if spec is None or spec.origin is None:
        raise FileNotFoundError("the viser package is not installed: expected it next to mujoco (pip install viser)")
    path = Path(spec.origin).parent / "client" / "build" / "index.html"
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing: expected viser's wheel to ship its built client")
    return path.read_bytes()
