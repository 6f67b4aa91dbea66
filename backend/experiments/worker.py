"""A sweep worker process: one JSON task per line on stdin, one JSON result line per task on stdout.

Run as ``python -m tableteach.experiments.worker``. Only JSON crosses the process boundary (the
project forbids pickle there). A failing task yields {"run": i, "error": "..."} and the worker
carries on; the parent decides what to do. stdout carries nothing but result lines.
"""

from __future__ import annotations

import json
import signal
import sys
from typing import TextIO

from .simulate import run_task_json


def serve(stdin: TextIO, stdout: TextIO) -> None:
    """Answer task lines until stdin closes."""
    for line in stdin:
        if not line.strip():
            continue
        try:
            result = run_task_json(line)
        except Exception as exc:  # reported to the parent, which stops the sweep with this message
            try:
                run = json.loads(line).get("run")
            except (ValueError, AttributeError):
                run = None
            result = json.dumps({"run": run, "error": f"{type(exc).__name__}: {exc}"})
        stdout.write(result + "\n")
        stdout.flush()


if __name__ == "__main__":
    # Ctrl-C reaches the whole process group; the parent handles it and stops its workers,
    # so a worker ignoring it spares the user one traceback per worker.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    serve(sys.stdin, sys.stdout)
