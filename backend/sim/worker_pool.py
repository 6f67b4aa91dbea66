"""Robot worker processes (tableteach.sim.execution_worker), started on first use and spoken to in JSON lines."""

from __future__ import annotations

import json
import logging
import queue
import select
import subprocess
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..robot import ExecutionPlan
from .recordings import RecordingId
from .scene import SCENE_XML

log = logging.getLogger(__name__)

WORKER_COMMAND = (sys.executable, "-m", "tableteach.sim.execution_worker")
REPLY_TIMEOUT_S = 120.0  # an execution takes about a second of CPU; a worker silent this long is stuck


class WorkerFailed(RuntimeError):
    """The worker process died, hung or failed on a request it accepted."""


class _Worker:
    """One worker process, started again if it has ended; used by one thread at a time."""

    def __init__(self, index: int, command: tuple[str, ...]) -> None:
        self.index = index
        self.command = command
        self.proc: subprocess.Popen[str] | None = None

    def ask(self, request: dict[str, Any]) -> dict[str, Any]:
        """Send one request and read its reply; WorkerFailed (and the process stopped) if that fails."""
        if self.proc is None or self.proc.poll() is not None:
            self.proc = subprocess.Popen(list(self.command), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                         encoding="utf-8")
        proc = self.proc
        assert proc.stdin is not None and proc.stdout is not None
        try:
            proc.stdin.write(json.dumps(request) + "\n")
            proc.stdin.flush()
            ready, _, _ = select.select([proc.stdout], [], [], REPLY_TIMEOUT_S)
            line = proc.stdout.readline() if ready else ""
        except OSError as exc:
            self.stop()
            raise WorkerFailed(f"robot worker {self.index} could not be reached: {exc}") from exc
        if not line:
            what = f"gave no reply within {REPLY_TIMEOUT_S:.0f} s"
            if ready:  # its output ended: the process is ending
                try:
                    what = f"ended with status {proc.wait(timeout=5)}"
                except subprocess.TimeoutExpired:
                    what = "closed its output"
            self.stop()
            raise WorkerFailed(f"robot worker {self.index} {what}")
        return json.loads(line)

    def stop(self) -> None:
        """End the process: closing its input ends it; kill it if it does not end soon."""
        proc, self.proc = self.proc, None
        if proc is None:
            return
        try:
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait(timeout=5)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        finally:
            if proc.stdout is not None:
                proc.stdout.close()


class ExecutionWorkers:
    """`size` worker processes; run() blocks the calling thread until a worker has worked the execution out."""

    def __init__(self, size: int, command: tuple[str, ...] = WORKER_COMMAND) -> None:
        if size < 1:
            raise ValueError(f"{size} robot workers: expected at least 1")
        self.size = size
        self._idle: queue.Queue[_Worker] = queue.Queue()
        self._all = [_Worker(i, command) for i in range(size)]
        for worker in self._all:
            self._idle.put(worker)
        self._closed = threading.Event()

    def run(self, data_dir: Path, seed: int, events: Sequence[str], rid: RecordingId, rate: float,
            scene: Path | None = None) -> ExecutionPlan:
        """The plan a worker worked out (its files saved under data_dir) on `scene` (None: the dinner table);
        ValueError for a sequence it refuses."""
        request: dict[str, Any] = {"data_dir": str(Path(data_dir).resolve()), "seed": seed, "events": list(events),
                                   "recording": rid.name, "rate": rate}
        if scene is not None and Path(scene) != SCENE_XML:
            request["scene"] = str(Path(scene).resolve())
        if self._closed.is_set():
            raise WorkerFailed("the robot workers are shut down: expected no new executions")
        worker = self._idle.get()
        try:
            try:
                reply = worker.ask(request)
            except WorkerFailed:
                if self._closed.is_set():
                    raise
                log.warning("robot worker %d failed; starting it again", worker.index, exc_info=True)
                reply = worker.ask(request)  # once more, on a fresh process
        finally:
            self._idle.put(worker)
        if not reply.get("ok"):
            error = str(reply.get("error", "no reason given"))
            raise ValueError(error) if reply.get("invalid") else WorkerFailed(f"robot worker failed: {error}")
        return ExecutionPlan(tuple(reply["events"]), tuple(frozenset(labels) for labels in reply["trace"]),
                             tuple(float(t) for t in reply["action_ends"]), viewable=bool(reply["viewable"]))

    def close(self) -> None:
        """Stop every worker process (waiting for the ones busy with an execution)."""
        self._closed.set()
        for _ in self._all:
            self._idle.get().stop()
