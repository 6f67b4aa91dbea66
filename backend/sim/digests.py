"""Names for motion that is worked out once and kept (shared executions, placement clips): a digest of what
decides it, the compiled scene and the code and library versions that make it included, so that a changed
scene, a changed robot or another MuJoCo never finds motion made before."""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import viser

from ..version import app_version
from .scene import load_scene

# The modules whose code decides a motion and its files: a change to any of them gives new digests.
MOTION_MODULES = ("arm.py", "physics.py", "scene.py", "clips.py", "motion_file.py", "viser_file.py", "view.py",
                  "work_out.py", "digests.py")


@lru_cache(maxsize=8)
def _scene_digest(scene: str) -> str:
    model, _layout = load_scene(Path(scene))
    buffer = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return hashlib.sha256(buffer.tobytes()).hexdigest()


def scene_digest(scene: Path | str) -> str:
    """The compiled model's digest (so a changed asset or include counts, not only the XML file)."""
    return _scene_digest(str(scene))


@lru_cache(maxsize=1)
def code_digest() -> str:
    """The digest of the motion-making modules' source and of the libraries' versions."""
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256(f"{app_version()} mujoco {mujoco.__version__} viser {viser.__version__}".encode())
    for name in MOTION_MODULES:
        digest.update(b"\0" + name.encode() + b"\0" + (here / name).read_bytes())
    return digest.hexdigest()


def digest_of(inputs: dict[str, Any]) -> str:
    """A 40-hex-digit name for JSON-ready inputs, the code's digest included."""
    text = json.dumps({**inputs, "code": code_digest()}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:40]
