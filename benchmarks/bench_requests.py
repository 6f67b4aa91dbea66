"""CPU per request: what each kind of participant request costs the server, measured from its CPU time.

Starts `tableteach serve` (trace robot, a temp SQLite file), creates the demo-like study, joins participants
and brings each to a demonstration step, then sends N requests of one kind at a time, one after another,
and divides the server's CPU time (/proc) by N. Polls are sent as the page sends them: with the ETag of the
previous answer (If-None-Match), so a poll that finds nothing new is answered 304.

    .venv/bin/python benchmarks/bench_requests.py --requests 300

It prints, per request kind, the server's CPU milliseconds per request (median of --repeats rounds) and the
share of 304 answers; and last: `get_me_ms X get_me_304_ms Y get_robot_ms Z tab_ms W` (medians).
"""

from __future__ import annotations

import argparse
import os
import secrets
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_server(folder: Path, token: str) -> tuple[subprocess.Popen[bytes], str]:
    """`tableteach serve` on a temp SQLite file with the trace robot; its process and URL."""
    port = _free_port()
    env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": token, "TABLETEACH_DATA_DIR": str(folder)}
    env.pop("TABLETEACH_DEV_MODE", None)
    proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--migrate", "--robot", "trace",
                             "--port", str(port), "--database-url", f"sqlite:///{folder / 'bench.db'}"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the server exited with {proc.returncode}")
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return proc, url
        except httpx.TransportError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("the server did not answer /healthz within 60 s")


def participant_at_demonstration(http: httpx.Client, study_id: str) -> str:
    """A new participant's token, brought to the first demonstration step."""
    joined = http.post(f"/api/v1/studies/{study_id}/join", json={"prolific_pid": f"bench-{secrets.token_hex(6)}"})
    joined.raise_for_status()
    state = joined.json()["state"]
    headers = {"Authorization": f"Bearer {state['token']}"}
    http.post("/api/v1/me/consent", json={"agree": True, "consent_version": state["consent"]["version"]},
              headers=headers).raise_for_status()
    http.post("/api/v1/me/instructions", headers=headers).raise_for_status()
    return str(state["token"])


def cpu_ms_per_request(pid: int, n: int, send: Callable[[], httpx.Response]) -> tuple[float, float]:
    """The server's CPU ms per request over n requests of `send`, and the share answered 304."""
    not_modified = 0
    before = _cpu_seconds(pid)
    for _ in range(n):
        response = send()
        if response.status_code == 304:
            not_modified += 1
        elif response.status_code >= 400:
            raise RuntimeError(f"HTTP {response.status_code}: {response.text[:200]}")
    return 1000 * (_cpu_seconds(pid) - before) / n, not_modified / n


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--requests", type=int, default=300, help="requests per kind and round")
    parser.add_argument("--repeats", type=int, default=5, help="rounds; the median is printed")
    args = parser.parse_args(argv)
    if args.requests < 10 or args.repeats < 1:
        parser.error("--requests must be at least 10 and --repeats at least 1")
    token = secrets.token_urlsafe(24)
    folder = Path(tempfile.mkdtemp(prefix="bench-requests-"))
    proc, url = start_server(folder, token)
    try:
        admin = {"Authorization": f"Bearer {token}"}
        with httpx.Client(base_url=url, timeout=30) as http:
            spec = {"name": "request benchmark", "tasks": [{"key": "task1"}], "conditions": ["active"],
                    "n_practice": 0, "n_demonstrations": 2, "n_queries": 2, "n_tests": 1}
            study = http.post("/api/v1/studies", json=spec, headers=admin).json()
            http.post(f"/api/v1/studies/{study['id']}/open", headers=admin).raise_for_status()
            me = {"Authorization": f"Bearer {participant_at_demonstration(http, study['id'])}"}
            etags: dict[str, str] = {}

            def poll(path: str) -> Callable[[], httpx.Response]:
                def send() -> httpx.Response:
                    headers = dict(me)
                    if path in etags:
                        headers["If-None-Match"] = etags[path]
                    response = http.get(path, headers=headers)
                    if "etag" in response.headers:
                        etags[path] = response.headers["etag"]
                    return response
                return send

            def fresh(path: str) -> Callable[[], httpx.Response]:
                return lambda: http.get(path, headers=me)

            tab = secrets.token_urlsafe(12)
            kinds: dict[str, Callable[[], httpx.Response]] = {
                "GET me (full answer)": fresh("/api/v1/me"),
                "GET me (poll with ETag)": poll("/api/v1/me"),
                "GET robot (full answer)": fresh("/api/v1/me/robot"),
                "GET robot (poll with ETag)": poll("/api/v1/me/robot"),
                "POST tab (lease renewal)": lambda: http.post("/api/v1/me/tab", json={"tab_id": tab}, headers=me),
                "GET healthz": lambda: http.get("/healthz"),
            }
            figures: dict[str, list[float]] = {k: [] for k in kinds}
            shares: dict[str, float] = {}
            for round_ in range(args.repeats):
                for name, send in kinds.items():
                    ms, share = cpu_ms_per_request(proc.pid, args.requests, send)
                    figures[name].append(ms)
                    shares[name] = share
                print(f"  round {round_ + 1}/{args.repeats} done", flush=True)
    finally:
        proc.terminate()
        proc.wait(timeout=15)
    print(f"\n{'request':<28}{'CPU ms/request':>16}{'  (min-max)':>16}{'304s':>7}")
    for name, xs in figures.items():
        print(f"{name:<28}{np.median(xs):>16.2f}{f'  ({min(xs):.2f}-{max(xs):.2f})':>16}{shares[name]:>7.0%}")
    print(f"machine load average {os.getloadavg()[0]:.1f}")
    med = {k: float(np.median(v)) for k, v in figures.items()}
    print(f"get_me_ms {med['GET me (full answer)']:.2f} get_me_304_ms {med['GET me (poll with ETag)']:.2f} "
          f"get_robot_ms {med['GET robot (full answer)']:.2f} tab_ms {med['POST tab (lease renewal)']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
