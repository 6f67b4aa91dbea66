"""Where runs execute: in this process, in a pool of JSON-line worker subprocesses, or on Dask.

Each backend takes JSON task strings and yields JSON result strings as runs finish (in any order).
The local pool deliberately avoids multiprocessing/concurrent.futures, which pickle: it starts
``python -m tableteach.experiments.worker`` processes and talks to them over pipes, one line each
way per task. With Dask, tasks and results are JSON strings too; Dask itself serialises them with
its own protocol (pickle among trusted cluster members), as its documentation says: only connect
to a scheduler you control.
"""

from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
from typing import Iterable, Iterator

from .simulate import run_task_json


class WorkerError(RuntimeError):
    """A run failed in a worker, or a worker died."""


def inline(tasks: Iterable[str]) -> Iterator[str]:
    """Run tasks one after another in this process."""
    for task in tasks:
        yield run_task_json(task)


def local_pool(tasks: Iterable[str], workers: int) -> Iterator[str]:
    """Run tasks on ``workers`` worker subprocesses, yielding results as they arrive."""
    todo: queue.Queue[str | None] = queue.Queue()
    n_tasks = 0
    for task in tasks:
        todo.put(task)
        n_tasks += 1
    workers = max(1, min(workers, n_tasks))
    done: queue.Queue[tuple[str, str | BaseException]] = queue.Queue()
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "tableteach.experiments.worker"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1,
        )
        for _ in range(workers)
    ]
    threads = [threading.Thread(target=_feed, args=(p, todo, done), daemon=True) for p in procs]
    for _ in procs:
        todo.put(None)  # one stop marker per worker, after all tasks
    try:
        for t in threads:
            t.start()
        for _ in range(n_tasks):
            kind, payload = done.get()
            if kind == "error":
                raise WorkerError(str(payload))
            yield payload  # type: ignore[misc]
    finally:
        _drain(todo)
        for _ in procs:
            todo.put(None)
        for p in procs:
            _stop(p)


def _feed(proc: subprocess.Popen, todo: "queue.Queue[str | None]", done: "queue.Queue") -> None:
    """Send one task at a time to a worker and pass its answers on (runs in a thread)."""
    assert proc.stdin is not None and proc.stdout is not None
    try:
        while (task := todo.get()) is not None:
            proc.stdin.write(task.rstrip("\n") + "\n")
            proc.stdin.flush()
            line = proc.stdout.readline()
            if not line:
                code = proc.wait()
                done.put(("error", f"a worker process exited with code {code} (its error is printed above)"))
                return
            error = json.loads(line).get("error")
            if error:
                done.put(("error", f"run {json.loads(task)['run']} failed in a worker: {error}"))
                return
            done.put(("ok", line.rstrip("\n")))
    except (OSError, ValueError) as exc:  # broken pipe or garbled line: the worker is gone
        done.put(("error", f"lost contact with a worker process: {exc}"))


def _drain(todo: "queue.Queue") -> None:
    """Drop tasks not yet started (and old stop markers) when the sweep ends early."""
    try:
        while True:
            todo.get_nowait()
    except queue.Empty:
        pass


def _stop(proc: subprocess.Popen) -> None:
    """Close a worker's input and make sure it exits."""
    try:
        if proc.stdin:
            proc.stdin.close()
    except OSError:
        pass
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def dask_cluster(tasks: Iterable[str], address: str) -> Iterator[str]:
    """Run tasks on an existing Dask cluster at ``address``, yielding results as they finish."""
    from distributed import Client, as_completed

    try:
        client = Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ValueError(f"cannot connect to the Dask scheduler at {address!r}: {exc}; "
                         "expected the address of a running scheduler, e.g. tcp://host:8786") from None
    try:
        futures = [client.submit(run_task_json, task, pure=False) for task in tasks]
        for future in as_completed(futures, loop=client.loop):
            try:
                yield future.result()
            except Exception as exc:
                raise WorkerError(f"a run failed on the Dask cluster: {type(exc).__name__}: {exc}") from exc
    finally:
        client.close()


def check_dask(address: str) -> None:
    """Fail early (ValueError) if no Dask scheduler answers at ``address``."""
    for _ in dask_cluster([], address):
        pass
