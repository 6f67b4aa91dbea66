"""docker-compose.yml and the Dockerfile agree with the settings and the CLI (no Docker engine needed)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import yaml

from tableteach.config import Settings, get_settings
from tableteach.db.migrate import REPO_ROOT

COMPOSE = yaml.safe_load((REPO_ROOT / "docker-compose.yml").read_text())
DOCKERFILE = (REPO_ROOT / "Dockerfile").read_text()


def test_services_run_postgres_then_migrations_then_the_app() -> None:
    services = COMPOSE["services"]
    assert set(services) == {"db", "migrate", "app", "proxy"}
    assert services["db"]["image"].startswith("postgres:")
    assert services["migrate"]["command"] == ["alembic", "upgrade", "head"]
    assert services["migrate"]["depends_on"]["db"]["condition"] == "service_healthy"
    assert services["app"]["command"][:2] == ["tableteach", "serve"]
    assert services["app"]["depends_on"]["migrate"]["condition"] == "service_completed_successfully"
    assert services["migrate"]["build"] == services["app"]["build"] == "."


def test_environment_names_are_settings_and_urls_point_at_the_db_service() -> None:
    fields = {f"TABLETEACH_{name.upper()}" for name in Settings.model_fields}
    for name in ("migrate", "app"):
        env = COMPOSE["services"][name]["environment"]
        assert set(env) <= fields, set(env) - fields
        url = env["TABLETEACH_DATABASE_URL"]
        assert url.startswith("postgresql+psycopg://") and "@db:5432/" in url
        db_env = COMPOSE["services"]["db"]["environment"]
        assert url.endswith("/" + db_env["POSTGRES_DB"]) and f"//{db_env['POSTGRES_USER']}:" in url
    assert "TABLETEACH_EXPERIMENTER_TOKEN" in COMPOSE["services"]["app"]["environment"]


def test_no_secret_is_written_into_the_files() -> None:
    text = (REPO_ROOT / "docker-compose.yml").read_text()
    for value in re.findall(r"(?:PASSWORD|TOKEN): (.*)", text):
        assert value.startswith("${") and ":?" in value, value
    assert "TOKEN=" not in DOCKERFILE and "PASSWORD" not in DOCKERFILE


def test_dockerfile_installs_the_postgres_driver_and_the_migrations() -> None:
    assert "psycopg" in DOCKERFILE and "pip install -e ." in DOCKERFILE
    assert "COPY alembic " in DOCKERFILE and "COPY alembic.ini" in DOCKERFILE
    assert "tableteach" in DOCKERFILE.splitlines()[-1]


def test_nginx_is_the_public_address_in_front_of_the_app_processes() -> None:
    services = COMPOSE["services"]
    proxy, app = services["proxy"], services["app"]
    assert proxy["image"].startswith("nginx:") and "./deploy/nginx.conf:/etc/nginx/nginx.conf:ro" in proxy["volumes"]
    assert proxy["depends_on"]["app"]["condition"] == "service_healthy"
    assert "ports" not in app and app["deploy"]["replicas"].startswith("${TABLETEACH_APP_PROCESSES")
    # All processes share one recording store (the .viser files any of them may serve).
    assert any(v.endswith(":" + app["environment"]["TABLETEACH_DATA_DIR"]) for v in app["volumes"])
    conf = (REPO_ROOT / "deploy" / "nginx.conf").read_text()
    assert "server app:8000" in conf and "listen 8080;" in conf and "hash $route_key consistent;" in conf


def _compose_environment(service: str, values: dict[str, str]) -> dict[str, str]:
    """A service's environment as compose would pass it: ${NAME:?...} and ${NAME:-default} substituted."""

    def substitute(text: str) -> str:
        def one(match: re.Match[str]) -> str:
            name, op, rest = match.group(1), match.group(2), match.group(3)
            if name in values:
                return values[name]
            assert op == ":-", f"compose would refuse to start without {name}: {rest}"
            return rest

        return re.sub(r"\$\{(\w+)(:\?|:-)([^}]*)\}", one, text)

    return {name: substitute(str(value)) for name, value in COMPOSE["services"][service]["environment"].items()}


def test_the_compose_deployment_shows_participants_the_3d_view(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The app built from the compose file's environment (only the database moved to a temp SQLite file and the
    data folder to tmp_path) runs the MuJoCo robot, and a participant in a task gets a 3D view."""
    import warnings

    from tableteach.db.migrate import upgrade_head
    from tableteach.web.app import create_app
    from tableteach.web.auth import generate_key

    from .helpers import bearer, to_teaching

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    key = generate_key()
    env = _compose_environment("app", {"POSTGRES_PASSWORD": "unused", "TABLETEACH_EXPERIMENTER_TOKEN": key})
    assert "TABLETEACH_ROBOT" not in env or env["TABLETEACH_ROBOT"] == "mujoco", env
    env["TABLETEACH_DATABASE_URL"] = f"sqlite:///{tmp_path / 'compose.db'}"
    env["TABLETEACH_DATA_DIR"] = str(tmp_path / "data")
    for name in [n for n in os.environ if n.startswith("TABLETEACH_")]:
        monkeypatch.delenv(name)  # only what the compose file sets
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    settings = get_settings()
    assert settings.robot == "mujoco"
    upgrade_head(settings.database_url)
    with TestClient(create_app(settings)) as client:
        exp = {"Authorization": f"Bearer {key}"}
        from .conftest import study_spec

        created = client.post("/api/v1/studies", json=study_spec(["active"]), headers=exp)
        assert created.status_code == 201, created.text
        study_id = created.json()["id"]
        assert client.post(f"/api/v1/studies/{study_id}/open", headers=exp).status_code == 200
        token, _state = to_teaching(client, study_id)
        view = client.post("/api/v1/me/view", headers=bearer(token)).json()
        assert view["available"] is True and view["url"].startswith(f"/p/{token}/viewer"), view
        page = client.get(f"/p/{token}")
        assert page.status_code == 200 and "participant.js" in page.text
