"""deploy/nginx.conf in front of two app processes on PostgreSQL: a participant's requests stick to one process,
and when that process is killed the next request goes to the other and the session carries on.

And the TLS front: HTTPS with a self-signed certificate made in the test, HSTS, plain HTTP redirected.

Runs Debian's nginx (package nginx-light) on free ports with the compose file's configuration, its upstream
pointed at the test processes and its certificate paths at the test's; skipped where nginx is not installed."""

from __future__ import annotations

import os
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


def self_signed_certificate(folder: Path) -> tuple[Path, Path]:
    """A self-signed certificate for 127.0.0.1 and localhost (openssl), as fullchain.pem and privkey.pem."""
    cert, key = folder / "fullchain.pem", folder / "privkey.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "2", "-subj", "/CN=127.0.0.1",
                    "-addext", "subjectAltName=IP:127.0.0.1,DNS:localhost", "-keyout", str(key), "-out", str(cert)],
                   check=True, capture_output=True)
    return cert, key


def _render(servers: list[ServerProcess], port: int, folder: Path, http_port: int | None = None) -> Path:
    """The repository's nginx.conf with the test's upstreams, ports (TLS on `port`, the redirect on `http_port`),
    a self-signed certificate and folders in tmp; it reports which upstream answered."""
    text = (REPO / "deploy" / "nginx.conf").read_text()
    upstream = "        server app:8000 max_fails=1 fail_timeout=10s;\n"
    for expected in (upstream, "listen 8080;", "listen 8443 ssl;", "/etc/nginx/certs/fullchain.pem",
                     "/etc/nginx/certs/privkey.pem", "root /var/www/acme;"):
        assert expected in text, expected
    text = text.replace(upstream, "".join(f"        server 127.0.0.1:{s.port} max_fails=1 fail_timeout=10s;\n"
                                          for s in servers))
    cert, key = self_signed_certificate(folder)
    (folder / "acme" / ".well-known" / "acme-challenge").mkdir(parents=True)
    text = text.replace("/etc/nginx/certs/fullchain.pem", str(cert)).replace("/etc/nginx/certs/privkey.pem", str(key))
    text = text.replace("root /var/www/acme;", f"root {folder / 'acme'};")
    text = text.replace("listen 8443 ssl;", f"listen 127.0.0.1:{port} ssl;\n"
                        "        add_header X-Upstream $upstream_addr always;")
    text = text.replace("listen 8080;", f"listen 127.0.0.1:{http_port or free_port()};")
    # As root, nginx's workers would run as nobody, who cannot read the test's private temp folder.
    user = "user root;\n" if os.geteuid() == 0 else ""
    text = text.replace("worker_processes auto;", f"{user}worker_processes 1;\npid {folder}/nginx.pid;\n"
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
def test_a_participant_sticks_to_one_process_and_moves_when_it_dies(
    postgres_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch  # noqa: F811
) -> None:
    env = {"TABLETEACH_DATA_DIR": str(tmp_path / "data")}
    servers = [ServerProcess(tmp_path / f"{name}.db", database_url=postgres_url, **env).start() for name in "ab"]
    port = free_port()
    conf = _render(servers, port, tmp_path)
    check = subprocess.run([NGINX, "-t", "-c", str(conf), "-p", str(tmp_path)], capture_output=True, text=True)
    assert check.returncode == 0, check.stderr
    proxy = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(tmp_path), "-g", "daemon off;"])
    monkeypatch.setenv("SSL_CERT_FILE", str(tmp_path / "fullchain.pem"))  # httpx trusts the test's certificate
    base = f"https://127.0.0.1:{port}"
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


@pytest.mark.skipif(not Path(NGINX).exists(), reason="Debian's nginx is not installed (apt-get install nginx-light)")
def test_the_proxy_terminates_tls_redirects_http_and_sends_hsts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    server = ServerProcess(tmp_path / "study.db").start()
    port, http_port = free_port(), free_port()
    conf = _render([server], port, tmp_path, http_port=http_port)
    proxy = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(tmp_path), "-g", "daemon off;"])
    monkeypatch.setenv("SSL_CERT_FILE", str(tmp_path / "fullchain.pem"))
    base = f"https://127.0.0.1:{port}"
    try:
        def answers() -> bool:
            try:
                return httpx.get(f"{base}/healthz", timeout=5).status_code > 0
            except httpx.TransportError:
                return False

        wait_until(answers, "nginx to answer over TLS")
        health = httpx.get(f"{base}/healthz", timeout=30)
        assert health.status_code == 200 and health.json()["status"] == "ok"
        assert health.headers["strict-transport-security"] == "max-age=31536000"
        # Every plain-HTTP address redirects to the same path over https.
        moved = httpx.get(f"http://127.0.0.1:{http_port}/study/abc/join?PROLIFIC_PID=x", timeout=5)
        assert moved.status_code == 301 and moved.headers["location"] == "https://127.0.0.1/study/abc/join?PROLIFIC_PID=x"
        # ... except the ACME challenge folder a certbot webroot renewal writes to.
        (tmp_path / "acme" / ".well-known" / "acme-challenge" / "probe").write_text("challenge-answer")
        acme = httpx.get(f"http://127.0.0.1:{http_port}/.well-known/acme-challenge/probe", timeout=5)
        assert acme.status_code == 200 and acme.text == "challenge-answer"
        # The app sees https (X-Forwarded-Proto): a joining participant's browser cookie is Secure.
        study_id = open_study(base, study_spec(["active"]))
        joined = httpx.post(f"{base}/api/v1/studies/{study_id}/join", json={}, timeout=10)
        assert joined.status_code == 201 and "secure" in joined.headers["set-cookie"].lower()
        # Plain HTTP on the TLS port is refused, and the certificate is really checked.
        assert httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=5).status_code == 400
        monkeypatch.delenv("SSL_CERT_FILE")
        with pytest.raises(httpx.ConnectError):
            httpx.get(f"{base}/healthz", timeout=5)
    finally:
        proxy.terminate()
        proxy.wait(timeout=10)
        server.stop()
