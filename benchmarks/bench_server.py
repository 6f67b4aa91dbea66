"""Load benchmark: N scripted teachers at once (threads) against one study server on SQLite.

Starts `tableteach serve` on a temp SQLite file (or uses --server), creates a study with the Active,
Random and Batch conditions, runs the teachers and prints sessions completed, request latency
p50/p99 and errors. Target: all complete, p99 under 200 ms, 0 errors.

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

from tableteach.client import ExperimenterClient, run_teacher


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_server(folder: Path, token: str) -> tuple[subprocess.Popen[bytes], str]:
    port = _free_port()
    env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": token}
    proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--port", str(port),
                             "--database-url", f"sqlite:///{folder / 'bench.db'}"],
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


def main() -> int:
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--teachers", type=int, default=50)
    parser.add_argument("--server", help="an existing server (default: start one on a temp SQLite file)")
    parser.add_argument("--token", help="experimenter token of --server")
    parser.add_argument("--think", type=float, default=0.0, help="pause between a teacher's requests, seconds")
    args = parser.parse_args()

    token = args.token or secrets.token_urlsafe(18)
    folder = Path(tempfile.mkdtemp(prefix="tableteach-bench-"))
    proc = None
    url = args.server
    if url is None:
        proc, url = _start_server(folder, token)
    try:
        exp = ExperimenterClient(url, token=token)
        study = exp.create_study({"name": "bench", "tasks": [{"key": "task1"}],
                                  "conditions": ["active", "random", "batch"],
                                  "questionnaire": [{"id": "overall", "text": "Overall", "kind": "rating10"}]})
        exp.open_study(study["id"])
        latencies: list[float] = []
        by_kind: dict[str, list[float]] = {}
        errors: list[str] = []
        completed = 0
        lock = threading.Lock()

        def record(name: str, seconds: float, status: int) -> None:
            with lock:
                latencies.append(seconds)
                by_kind.setdefault(name.rsplit("/", 1)[-1] if "/me" in name else name.split()[0] + " join", []).append(seconds)
                if status >= 400:
                    errors.append(f"{name}: HTTP {status}")
            if args.think:
                time.sleep(args.think)

        def teacher(i: int) -> None:
            nonlocal completed
            try:
                run = run_teacher(url, study["id"], ["task1"], seed=i, on_request=record, poll_seconds=0.05)
                with lock:
                    completed += run.completion_code is not None
            except Exception as exc:  # noqa: BLE001 - every failure is a figure of this benchmark
                with lock:
                    errors.append(f"teacher {i}: {type(exc).__name__}: {exc}")

        started = time.perf_counter()
        threads = [threading.Thread(target=teacher, args=(i,)) for i in range(args.teachers)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.perf_counter() - started
        ms = np.array(latencies) * 1000
        result = {
            "teachers": args.teachers, "completed": completed, "requests": len(latencies), "errors": len(errors),
            "p50_ms": round(float(np.percentile(ms, 50)), 1), "p99_ms": round(float(np.percentile(ms, 99)), 1),
            "max_ms": round(float(ms.max()), 1), "wall_s": round(wall, 1),
            "requests_per_s": round(len(latencies) / wall, 1), "think_s": args.think,
        }
        print(json.dumps(result))
        for kind, values in sorted(by_kind.items()):
            v = np.array(values) * 1000
            print(f"  {kind:<12} n={v.size:<5} p50={np.percentile(v, 50):7.1f} ms  p99={np.percentile(v, 99):7.1f} ms")
        for line in errors[:10]:
            print("error:", line, file=sys.stderr)
        exp.close()
        ok = completed == args.teachers and not errors and result["p99_ms"] < 200
        return 0 if ok else 1
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=10)


if __name__ == "__main__":
    sys.exit(main())
