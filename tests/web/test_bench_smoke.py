"""The server benchmark runs: its teachers complete sessions and it reports the figures (no timing asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_server.py"


def test_the_server_benchmark_runs_its_teachers_to_completion() -> None:
    out = subprocess.run([sys.executable, str(BENCH), "--teachers", "3", "--think", "0", "--no-flat-out"],
                         capture_output=True, text=True, timeout=300)
    lines = out.stdout.splitlines()
    result = json.loads(next(line for line in lines if line.startswith("{")))
    assert result["teachers"] == 3 and result["completed"] == 3 and result["errors"] == 0, out.stdout + out.stderr
    assert result["requests"] > 3 * 10 and result["p99_ms"] >= result["p50_ms"] > 0
    assert result["server_cpu_ms_per_request"] is not None
    assert any(line.strip().startswith("join") for line in lines)
    assert ("target met" in out.stdout) == (out.returncode == 0)  # the exit status follows the printed verdict
