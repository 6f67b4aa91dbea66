"""`tableteach serve` with a probe for bench_views.py: on SIGUSR1 the server writes, as JSON to the file that
TABLETEACH_BENCH_PROBE names, what its live views hold (views in the view hub, viser's clients and connections, its
threads by name and, with TABLETEACH_BENCH_TRACE=1, the Python heap as tracemalloc counts it).

    python benchmarks/server_probe.py serve --port 8000 --database-url sqlite:///...

The probe only reads counters (no gc.get_objects: holding every object from a signal handler can break another
thread's tuple being built); the handler runs on the main thread, between the event loop's callbacks.
"""

from __future__ import annotations

import gc
import json
import os
import re
import signal
import sys
import threading
import tracemalloc
from collections import Counter
from pathlib import Path
from types import FrameType
from typing import Any

TRACE = os.environ.get("TABLETEACH_BENCH_TRACE") == "1"
if TRACE:
    tracemalloc.start()

from tableteach.sim import view_hub  # noqa: E402 (after tracemalloc starts, so the app's imports are traced too)

HUBS: list[view_hub.ViewHub] = []
_hub_init = view_hub.ViewHub.__init__


def _noted_init(self: view_hub.ViewHub, *args: Any, **kwargs: Any) -> None:
    _hub_init(self, *args, **kwargs)
    HUBS.append(self)


view_hub.ViewHub.__init__ = _noted_init  # type: ignore[method-assign]


def report() -> dict[str, Any]:
    """What the server's views hold now."""
    gc.collect()
    servers = [hub._server for hub in HUBS if hub._server is not None]
    names = Counter(_owner(thread, servers) for thread in threading.enumerate())
    return {"views": sum(hub.views() for hub in HUBS),
            "viser_clients": sum(len(server.get_clients()) for server in servers),
            "connections": sum(len(server._websock_server._client_state_from_id) for server in servers),
            "python_heap": tracemalloc.get_traced_memory()[0] if TRACE else None,
            "threads": dict(sorted(names.items()))}


def _owner(thread: threading.Thread, servers: list[Any]) -> str:
    """Whose thread it is: viser's (its event loop, its executor), anyio's (starlette's thread pool), or its name."""
    for server in servers:
        if thread is server._websock_server._server_thread:
            return "viser event loop"
        if thread in server._thread_executor._threads:
            return "viser executor"
    if thread.name.startswith("AnyIO worker thread"):
        return "anyio worker (starlette's thread pool)"
    return re.sub(r"\d+", "N", thread.name)


def _write(_signum: int, _frame: FrameType | None) -> None:
    path = Path(os.environ["TABLETEACH_BENCH_PROBE"])
    path.with_suffix(".tmp").write_text(json.dumps(report()))
    path.with_suffix(".tmp").replace(path)


if __name__ == "__main__":
    signal.signal(signal.SIGUSR1, _write)
    from tableteach.cli import main

    sys.exit(main(sys.argv[1:]))
