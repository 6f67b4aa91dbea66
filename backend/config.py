"""Server settings (pydantic-settings): read from TABLETEACH_* environment variables; nothing built at import."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

DEFAULT_DATABASE_URL = "sqlite:///var/tableteach.db"
ROBOTS = ("trace", "mujoco")
DEFAULT_DATA_DIR = "var/data"


class Settings(BaseSettings):
    """Everything the server reads from its environment; tests build it directly."""

    model_config = SettingsConfigDict(env_prefix="TABLETEACH_", extra="ignore")

    database_url: str = Field(DEFAULT_DATABASE_URL,
        description="SQLAlchemy URL: sqlite:///path or postgresql+psycopg://...")
    dev_mode: bool = Field(False, description="allow a generated experimenter token and the demo study")
    experimenter_token: SecretStr | None = Field(None,
        description="experimenter API token or password (hashed at startup)")
    experimenter_token_hash: str | None = Field(None,
        description="pbkdf2 hash of the token (from `tableteach hash-token`)")
    robot: Literal["trace", "mujoco"] = Field(
        "trace", description="robot implementation: 'trace' (no physics) or 'mujoco' (simulated arm, 3D view)")
    robot_seconds_per_object: float = Field(0.0, ge=0.0, le=60.0,
        description="how long the trace robot takes per placement")
    robot_speed: float = Field(1.0, gt=0.0, le=50.0,
        description="MuJoCo robot: playback speed of its motion (1 = real time)")
    viewer_idle_minutes: float = Field(10.0, gt=0.0,
        description="stop a participant's 3D view this long after its last use")
    data_dir: Path = Field(Path(DEFAULT_DATA_DIR),
        description="folder for files besides the database (robot recordings)")
    public_url: str | None = Field(None, description="base URL printed in links, e.g. https://study.example.org")
    active_minutes: float = Field(60.0, gt=0,
        description="a participant counts as active this long after their last request")
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)


def get_settings() -> Settings:
    """Settings from the environment (a fresh object on each call; no import-time singleton)."""
    return Settings()
