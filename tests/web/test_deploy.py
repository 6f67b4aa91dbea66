"""docker-compose.yml and the Dockerfile agree with the settings and the CLI (no Docker engine needed)."""

from __future__ import annotations

import re

import yaml

from tableteach.config import Settings
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
