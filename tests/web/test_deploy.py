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
    assert set(services) == {"db", "migrate", "app", "proxy", "backup"}
    assert services["db"]["image"].startswith("postgres:")
    assert services["migrate"]["command"] == ["alembic", "upgrade", "head"]
    assert services["migrate"]["depends_on"]["db"]["condition"] == "service_healthy"
    assert services["app"]["command"][:2] == ["tableteach", "serve"]
    assert services["app"]["depends_on"]["migrate"]["condition"] == "service_completed_successfully"
    assert services["migrate"]["build"] == services["app"]["build"] == "."


def test_environment_names_are_settings_and_urls_point_at_the_db_service() -> None:
    fields = {f"TABLETEACH_{name.upper()}" for name in Settings.model_fields}
    for name in ("migrate", "app", "backup"):
        env = COMPOSE["services"][name]["environment"]
        assert {n for n in env if n.startswith("TABLETEACH_")} <= fields, set(env) - fields
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


def _stages() -> list[list[str]]:
    """The Dockerfile's instructions (comments and continuation lines joined), split at each FROM."""
    text = re.sub(r"\\\n\s*", " ", DOCKERFILE)
    lines = [line.strip() for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    stages: list[list[str]] = []
    for line in lines:
        if line.startswith("FROM "):
            stages.append([])
        stages[-1].append(line)
    return stages


def test_dockerfile_installs_the_postgres_driver_and_the_migrations() -> None:
    assert "psycopg" in DOCKERFILE and "-e ." in DOCKERFILE
    assert "COPY alembic " in DOCKERFILE and "COPY alembic.ini" in DOCKERFILE
    assert "tableteach" in DOCKERFILE.splitlines()[-1]


def test_dockerfile_structure_pinned_multi_stage_non_root() -> None:
    """What this checks is the text of the Dockerfile, not a built image (there is no Docker engine here): every
    pip install uses constraints.txt, the build stage's virtualenv is copied into a second stage, that stage
    has pg_dump's package for backups, and its last USER is not root."""
    build, runtime = _stages()
    assert build[0].endswith(" AS build") and not runtime[0].endswith(" AS build")
    assert build[0].split()[1] == runtime[0].split()[1]  # one base image: the copied virtualenv's Python matches
    installs = [line for stage in (build, runtime) for line in stage if "pip install" in line]
    assert installs and all("--constraint constraints.txt" in line for line in installs), installs
    assert "COPY constraints.txt ./" in build
    assert "COPY --from=build /opt/venv /opt/venv" in runtime
    assert not any("pip install" in line for line in runtime)
    assert any("postgresql-client" in line for line in runtime)
    users = [line.split()[1] for line in runtime if line.startswith("USER ")]
    assert users and users[-1] not in ("root", "0")
    assert runtime[-1].startswith("CMD ") and runtime.index(f"USER {users[-1]}") < len(runtime) - 1


def test_constraints_pin_every_runtime_dependency() -> None:
    """constraints.txt names an exact version (==) of every dependency in pyproject.toml and psycopg."""
    import tomllib

    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]
    pinned = {}
    for line in (REPO_ROOT / "constraints.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            name, _, version = line.partition("==")
            pinned[name.strip().lower().replace("_", "-")] = version
    for requirement in [*project["dependencies"], "psycopg[binary]"]:
        name = re.split(r"[\[<>=;! ]", requirement, maxsplit=1)[0].lower().replace("_", "-")
        assert pinned.get(name), f"{name} is not pinned in constraints.txt"


def test_nginx_is_the_public_address_in_front_of_the_app_processes() -> None:
    services = COMPOSE["services"]
    proxy, app = services["proxy"], services["app"]
    assert proxy["image"].startswith("nginx:") and "./deploy/nginx.conf:/etc/nginx/nginx.conf:ro" in proxy["volumes"]
    assert "./deploy/certs:/etc/nginx/certs:ro" in proxy["volumes"]
    assert [p.split(":")[-1] for p in proxy["ports"]] == ["8080", "8443"]
    assert proxy["depends_on"]["app"]["condition"] == "service_healthy"
    assert "ports" not in app and app["deploy"]["replicas"].startswith("${TABLETEACH_APP_PROCESSES")
    # All processes share one recording store (the .viser files any of them may serve).
    assert any(v.endswith(":" + app["environment"]["TABLETEACH_DATA_DIR"]) for v in app["volumes"])
    conf = (REPO_ROOT / "deploy" / "nginx.conf").read_text()
    assert "server app:8000" in conf and "listen 8443 ssl;" in conf and "hash $route_key consistent;" in conf
    assert "return 301 https://$host$request_uri;" in conf and "Strict-Transport-Security" in conf


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
    env = _compose_environment("app", {"POSTGRES_PASSWORD": "unused", "TABLETEACH_EXPERIMENTER_TOKEN": key,
                                       "TABLETEACH_PUBLIC_URL": "https://study.example.org"})
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


def test_the_scheduled_backup_service_makes_backups_and_keeps_making_them(tmp_path: Path) -> None:
    """The backup service's shell loop, as compose would run it ($$ is compose's escape for $), on SQLite with a
    one-second interval: it writes restorable backups one after another."""
    import subprocess
    import sys
    import time

    from tableteach.db.backup import read_manifest
    from tableteach.db.migrate import upgrade_head

    service = COMPOSE["services"]["backup"]
    assert service["entrypoint"] == ["sh", "-c"] and service["depends_on"]["migrate"]["condition"] == \
        "service_completed_successfully"
    assert any(v.startswith("recordings:") and v.endswith(":ro") for v in service["volumes"])
    script = service["command"][0].replace("$$", "$")
    env = {**_compose_environment("backup", {"POSTGRES_PASSWORD": "unused"})}
    assert env["BACKUP_DIR"] in {v.split(":")[1] for v in service["volumes"]}
    url = f"sqlite:///{tmp_path / 'study.db'}"
    upgrade_head(url)
    env.update(TABLETEACH_DATABASE_URL=url, TABLETEACH_DATA_DIR=str(tmp_path / "data"),
               BACKUP_DIR=str(tmp_path / "backups"), BACKUP_INTERVAL_SECONDS="1",
               PATH=f"{Path(sys.executable).parent}:{os.environ['PATH']}")
    (tmp_path / "backups").mkdir()
    loop = subprocess.Popen(["sh", "-c", script], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while len(list((tmp_path / "backups").glob("tableteach-*.tar.gz"))) < 2:
            assert loop.poll() is None, loop.communicate()
            assert time.monotonic() < deadline, "the loop did not make two backups"
            time.sleep(0.2)
    finally:
        loop.kill()
        loop.communicate()
    for archive in sorted((tmp_path / "backups").glob("tableteach-*.tar.gz"))[:2]:
        assert read_manifest(archive)["database"]["kind"] == "sqlite"
