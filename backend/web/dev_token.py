"""Dev mode's experimenter token, kept across restarts in a file under the data folder (never used in production)."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

FILENAME = "dev-experimenter-token"


def dev_token_path(data_dir: Path | str) -> Path:
    """Where dev mode keeps its generated experimenter token."""
    return Path(data_dir) / FILENAME


def persistent_dev_token(data_dir: Path | str) -> str:
    """The dev token stored under data_dir, made (readable by this user only) on first use."""
    path = dev_token_path(data_dir)
    try:
        token = path.read_text(encoding="utf-8").strip()
        if token.startswith("dev-") and len(token) >= 20:
            return token
    except FileNotFoundError:
        pass
    token = "dev-" + secrets.token_urlsafe(18)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(token + "\n")
    return token
