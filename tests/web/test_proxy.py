"""deploy/nginx.conf in front of two app processes on PostgreSQL: a participant's requests stick to one process,
and when that process is killed the next request goes to the other and the session carries on.

Runs Debian's nginx (package nginx-light) on a free port with the compose file's configuration, its upstream
pointed at the two test processes; skipped where nginx is not installed."""

from __future__ import annotations

import shutil
import subprocess
from collections import Counter
from pathlib import Path

import httpx
import pytest

from tableteach.client import ParticipantClient, run_teacher

from tests.waiting import wait_until

from ..conftest import REPO
from .conftest import ServerProcess, free_port, open_study, study_spec
from .test_postgres import postgres_url  # noqa: F401 - the module's throwaway PostgreSQL cluster

pytestmark = pytest.mark.slow
NGINX = shutil.which("nginx") or "/usr/sbin/nginx"


def _render(servers: list[ServerProcess], port: int, folder: Path) -> Path:
    """The repository's nginx.conf with the test's upstreams and port; it reports which upstream answered."""
    text = (REPO / "deploy" / "nginx.conf").read_text()
    upstream = "        server app:8000 max_fails=1 fail_timeout=10s;\n"
    assert upstream in text and "listen 8080;" in text
    text = text.replace(upstream, "".join(f"        server 127.0.0.1:{s.port} max_fails=1 fail_timeout=10s;\n"
                                          for s in servers))
    text = text.replace("listen 8080;", f"listen 127.0.0.1:{port};\n"
                        "        add_header X-Upstream $upstream_addr always;")
    text = text.replace("worker_processes auto;", f"worker_processes 1;\npid {folder}/nginx.pid;\n"
                        f"error_log {folder}/error.log;")
    text = text.replace("http {", f"http {{\n    access_log off;\n    client_body_temp_path {folder}/body;\n"
                        f"    proxy_temp_path {folder}/proxy;", 1)
    conf = folder / "nginx.conf"
    conf.write_text(text)
    return conf


def _healthy(base: str) -> bool:
    """Whether /healthz answers 200 through the proxy (False while nothing listens yet)."""
    try:
        return httpx.get(f"{base}/healthz", timeout=5).status_code == 200
    except httpx.TransportError:
        return False


def _count(served: Counter[str], response: httpx.Response) -> None:
    """Count which upstream answered a participant's request (the join has no token yet, so it is spread)."""
    if "authorization" in response.request.headers:
        served.update([response.headers.get("x-upstream", "?")])


@pytest.mark.skipif(not Path(NGINX).exists(), reason="Debian's nginx is not installed (apt-get install nginx-light)")
def test_a_participant_sticks_to_one_process_and_moves_when_it_dies(postgres_url: str, tmp_path: Path) -> None:  # noqa: F811
    env = {"TABLETEACH_DATA_DIR": str(tmp_path / "data")}
    servers = [ServerProcess(tmp_path / f"{name}.db", database_url=postgres_url, **env).start() for name in "ab"]
    port = free_port()
    conf = _render(servers, port, tmp_path)
    check = subprocess.run([NGINX, "-t", "-c", str(conf), "-p", str(tmp_path)], capture_output=True, text=True)
    assert check.returncode == 0, check.stderr
    proxy = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(tmp_path), "-g", "daemon off;"])
    base = f"http://127.0.0.1:{port}"
    try:
        wait_until(lambda: _healthy(base), "nginx to answer /healthz", interval=0.1)
        study_id = open_study(base, study_spec(["active"]))
        upstreams: list[Counter[str]] = []
        tokens = []
        for seed in range(16):  # participants until both processes have some
            if len({a for served in upstreams for a in served}) == 2 and seed >= 4:
                break
            served: Counter[str] = Counter()
            api = ParticipantClient(base)
            api.http.event_hooks["response"] = [lambda r, s=served: _count(s, r)]
            run_teacher(base, study_id, ["task1"], seed=seed, client=api, stop_after=4)
            upstreams.append(served)
            tokens.append(api.token)
        assert all(len(served) == 1 for served in upstreams), upstreams  # sticky: one process per participant
        assert len({next(iter(served)) for served in upstreams}) == 2, upstreams  # both processes are used

        victim_address = next(iter(upstreams[0]))
        victim = next(s for s in servers if victim_address.endswith(f":{s.port}"))
        survivor = next(s for s in servers if s is not victim)
        victim.kill()
        api = ParticipantClient(base, token=tokens[0])
        moved: Counter[str] = Counter()
        api.http.event_hooks["response"] = [lambda r: _count(moved, r)]
        finished = run_teacher(base, study_id, ["task1"], seed=0, client=api)
        assert finished.completion_code
        # Every answer came from the survivor (nginx may first try the dead one, then names both).
        assert all(address.endswith(f"127.0.0.1:{survivor.port}") for address in moved), moved

        # Wrong experimenter keys count per client address: the proxy passes the one it saw, so a client that
        # writes its own X-Forwarded-For does not escape the limit.
        statuses = [httpx.get(f"{base}/api/v1/studies", timeout=10, headers={
            "Authorization": "Bearer wrong-key", "X-Forwarded-For": f"203.0.113.{i}"}).status_code for i in range(21)]
        assert statuses[:20] == [401] * 20 and statuses[20] == 429, statuses
    finally:
        proxy.terminate()
        proxy.wait(timeout=10)
        for server in servers:
            server.stop()
