"""A short run of the fault-injection benchmark (benchmarks/faults.py): kill -9 while the robot places and while
it works an execution out; each participant finishes with only their page's own reads, nothing acknowledged lost."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow
FAULTS = Path(__file__).resolve().parents[2] / "benchmarks" / "faults.py"


def test_participants_finish_after_kills_during_placements_and_executions(capsys: pytest.CaptureFixture[str]) -> None:
    spec = importlib.util.spec_from_file_location("faults", FAULTS)
    assert spec is not None and spec.loader is not None
    faults = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = faults  # its dataclasses look their module up
    spec.loader.exec_module(faults)
    status = faults.main(["--seeds", "2", "--faults", "kill_placing,kill_working_out"])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "sessions 2 finished 2 stranded 0" in out and "lost_acks 0" in out
    assert "kills 2" in out
