"""Load benchmark: N scripted teachers at once (threads) against one study server on SQLite.

Starts `tableteach serve` on a temp SQLite file (or uses --server), creates a study with the Active,
Random and Batch conditions, and runs two scenarios, each with all teachers starting at the same instant:

- paced: each teacher pauses --think seconds (default 1) between its requests. A person takes several
  seconds per click, so this is still far busier than 50 participants. The target applies here:
  all sessions complete, p99 under 200 ms, 0 errors.
- flat out: no pauses. The server is saturated, so latency is queueing (Little's law: mean latency =
  teachers / throughput); this reports the throughput and the latency at saturation.

With --dashboard, an experimenter's dashboard is open during both: it polls the live table and the learning
curves every 4 s, as the page does, and its latencies are reported apart from the teachers'.

It prints sessions completed, request latency p50/p99 per action, errors, requests per second and the
server's CPU time per request (when it started the server). Exit status 1 if the paced target is missed.

    .venv/bin/python benchmarks/bench_server.py --teachers 50
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np

from tableteach.client import ExperimenterClient, ParticipantClient, run_teacher

TARGET_P99_MS = 200.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_server(folder: Path, token: str) -> tuple[subprocess.Popen[bytes], str]:
    port = _free_port()
    # Every simulated participant joins from 127.0.0.1: lift the per-address join limit for the benchmark.
    env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": token, "TABLETEACH_JOINS_PER_ADDRESS": "100000"}
    proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--migrate", "--robot", "trace",
                             "--port", str(port), "--database-url", f"sqlite:///{folder / 'bench.db'}"],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    for _ in range(300):
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return proc, url
        except httpx.TransportError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the server did not start")


def _cpu_seconds(pid: int) -> float | None:
    """User + system CPU time of a process (Linux /proc), or None where that is not available."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def _action(name: str) -> str:
    """'POST /api/v1/me/placements' -> 'placements'; 'POST /api/v1/studies/x/join' -> 'join'."""
    return name.rsplit("/", 1)[-1]


DASHBOARD_POLL_S = 4.0  # frontend/dashboard.js POLL_MS


class _Dashboard:
    """An experimenter's open dashboard: polls /live then /curves, recording latencies and failures."""

    def __init__(self, url: str, study_id: str, token: str) -> None:
        self.http = httpx.Client(base_url=url, headers={"Authorization": f"Bearer {token}"}, timeout=60)
        self.study_id = study_id
        self.latencies: dict[str, list[float]] = {}
        self.errors: list[str] = []
        self.stop = threading.Event()

    def poll(self) -> None:
        """One refresh of the page."""
        for name in ("live", "curves"):
            started = time.perf_counter()
            response = self.http.get(f"/api/v1/studies/{self.study_id}/{name}")
            self.latencies.setdefault(f"dashboard {name}", []).append(time.perf_counter() - started)
            if response.status_code != 200:
                self.errors.append(f"dashboard {name}: HTTP {response.status_code}")

    def watch(self) -> None:
        """Refresh every DASHBOARD_POLL_S until stopped."""
        while not self.stop.wait(DASHBOARD_POLL_S):
            self.poll()
        self.http.close()


def run_scenario(url: str, study_id: str, teachers: int, think: float, server_pid: int | None,
                 dashboard_token: str | None = None) -> dict:
    """All teachers start at once (after their clients are built) and complete a session each."""
    latencies: list[float] = []
    by_action: dict[str, list[float]] = {}
    errors: list[str] = []
    completed = 0
    lock = threading.Lock()

    def record(name: str, seconds: float, status: int) -> None:
        with lock:
            latencies.append(seconds)
            by_action.setdefault(_action(name), []).append(seconds)
            if status >= 400:
                errors.append(f"{name}: HTTP {status}")
        if think:
            time.sleep(think)

    # Clients are built before the start: building one (TLS defaults included) takes the client's GIL
    # for milliseconds, which would otherwise be counted in the other teachers' join latencies.
    clients = [ParticipantClient(url, on_request=record) for _ in range(teachers)]
    start = threading.Barrier(teachers + 1)

    def teacher(i: int) -> None:
        nonlocal completed
        start.wait()
        try:
            run = run_teacher(url, study_id, ["task1"], seed=i, on_request=record, poll_seconds=0.05,
                              client=clients[i])
            with lock:
                completed += run.completion_code is not None
        except Exception as exc:  # noqa: BLE001 - every failure is a figure of this benchmark
            with lock:
                errors.append(f"teacher {i}: {type(exc).__name__}: {exc}")
        finally:
            clients[i].close()

    threads = [threading.Thread(target=teacher, args=(i,)) for i in range(teachers)]
    for t in threads:
        t.start()
    dashboard = None if dashboard_token is None else _Dashboard(url, study_id, dashboard_token)
    watcher = None
    if dashboard is not None:
        dashboard.poll()  # the experimenter has the page open before the participants arrive
        watcher = threading.Thread(target=dashboard.watch)
        watcher.start()
    cpu_before = _cpu_seconds(server_pid) if server_pid else None
    started = time.perf_counter()
    start.wait()
    for t in threads:
        t.join()
    wall = time.perf_counter() - started
    if dashboard is not None and watcher is not None:
        dashboard.stop.set()
        watcher.join()
        errors += dashboard.errors
    cpu_after = _cpu_seconds(server_pid) if server_pid else None
    ms = np.array(latencies) * 1000
    result = {
        "think_s": think, "teachers": teachers, "completed": completed, "requests": len(latencies),
        "errors": len(errors), "p50_ms": round(float(np.percentile(ms, 50)), 1),
        "p99_ms": round(float(np.percentile(ms, 99)), 1), "max_ms": round(float(ms.max()), 1),
        "wall_s": round(wall, 1), "requests_per_s": round(len(latencies) / wall, 1),
        "server_cpu_ms_per_request": (round(1000 * (cpu_after - cpu_before) / len(latencies), 2)
                                      if cpu_before is not None and cpu_after is not None else None),
        "by_action": {name: {"n": len(v), "p50_ms": round(float(np.percentile(np.array(v) * 1000, 50)), 1),
                             "p99_ms": round(float(np.percentile(np.array(v) * 1000, 99)), 1)}
                      for name, v in sorted(by_action.items())},
        "dashboard": {name: {"n": len(v), "p50_ms": round(float(np.percentile(np.array(v) * 1000, 50)), 1),
                             "max_ms": round(float(np.max(v) * 1000), 1)}
                      for name, v in sorted(dashboard.latencies.items() if dashboard else [])},
        "error_samples": errors[:10],
    }
    return result


def _print(title: str, result: dict) -> None:
    print(f"== {title}")
    print(json.dumps({k: v for k, v in result.items() if k not in ("by_action", "dashboard", "error_samples")}))
    for name, row in result["by_action"].items():
        print(f"  {name:<17} n={row['n']:<5} p50={row['p50_ms']:7.1f} ms  p99={row['p99_ms']:7.1f} ms")
    for name, row in result["dashboard"].items():
        print(f"  {name:<17} n={row['n']:<5} p50={row['p50_ms']:7.1f} ms  max={row['max_ms']:7.1f} ms")
    for line in result["error_samples"]:
        print("error:", line, file=sys.stderr)


def main() -> int:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teachers", type=int, default=50)
    parser.add_argument("--think", type=float, default=1.0,
                        help="paced scenario: pause between a teacher's requests, seconds (default 1)")
    parser.add_argument("--no-flat-out", action="store_true", help="skip the scenario without pauses")
    parser.add_argument("--dashboard", action="store_true",
                        help="keep an experimenter's dashboard polling the live table and curves meanwhile")
    parser.add_argument("--server", help="an existing server (default: start one on a temp SQLite file)")
    parser.add_argument("--token", help="experimenter token of --server")
    args = parser.parse_args()
    if args.teachers < 1 or args.think < 0:
        parser.error("--teachers must be at least 1 and --think at least 0")

    token = args.token or secrets.token_urlsafe(32)  # a generated key, as the server requires
    proc = None
    url = args.server
    if url is None:
        proc, url = _start_server(Path(tempfile.mkdtemp(prefix="tableteach-bench-")), token)
    try:
        exp = ExperimenterClient(url, token=token)
        study = exp.create_study({"name": "bench", "tasks": [{"key": "task1"}],
                                  "conditions": ["active", "random", "batch"],
                                  "questionnaire": [{"id": "overall", "text": "Overall", "kind": "rating10"}]})
        exp.open_study(study["id"])
        pid = proc.pid if proc is not None else None
        watcher_token = token if args.dashboard else None
        paced = run_scenario(url, study["id"], args.teachers, args.think, pid, watcher_token)
        watching = ", dashboard open" if args.dashboard else ""
        _print(f"paced: {args.teachers} teachers, {args.think:g} s between a teacher's requests{watching} (target: "
               f"all complete, p99 < {TARGET_P99_MS:g} ms, 0 errors)", paced)
        ok = paced["completed"] == args.teachers and not paced["errors"] and paced["p99_ms"] < TARGET_P99_MS
        print(f"   target {'met' if ok else 'NOT met'}")
        if not args.no_flat_out:
            flat = run_scenario(url, study["id"], args.teachers, 0.0, pid, watcher_token)
            _print(f"flat out: {args.teachers} teachers, no pauses{watching} (saturation; latency is queueing)", flat)
        exp.close()
        return 0 if ok else 1
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=10)


if __name__ == "__main__":
    sys.exit(main())
