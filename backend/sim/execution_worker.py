"""A robot worker process: works executions out (physics, recording, .viser file) for its parent server.

Run as `python -m tableteach.sim.execution_worker` by tableteach.sim.worker_pool. It reads one JSON request
per line on stdin and answers one JSON line on stdout; it ends when stdin closes (its server stopped or
died). Keeping this CPU work (about a second per execution, most of it Python that holds the interpreter
lock) out of the server process keeps the server's requests fast.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import sys
from pathlib import Path
from typing import Any

from .clips import ClipCache, clip_folder
from .recordings import RecordingId
from .scene import SCENE_XML
from .work_out import StudioSource, work_out_execution

log = logging.getLogger("tableteach.sim.execution_worker")

WORKER_NICENESS = 10


def answer(studio: StudioSource, request: dict[str, Any], clips: ClipCache | None = None) -> dict[str, Any]:
    """The plan for one request, as JSON-ready data."""
    if clips is not None:
        clips.folder = clip_folder(request["data_dir"])  # the server's clips, on its data folder
    scene = Path(request["scene"]) if request.get("scene") else SCENE_XML  # a study's own objects, or the dinner
    plan = work_out_execution(studio, Path(request["data_dir"]), int(request["seed"]), list(request["events"]),
                              RecordingId.parse(request["recording"]), float(request["rate"]), clips, scene)
    return {"ok": True, "events": list(plan.events), "trace": [sorted(labels) for labels in plan.trace],
            "action_ends": list(plan.action_ends), "viewable": plan.viewable}


def serve(requests: Any, replies: Any) -> None:
    """Answer each request line until the input ends."""
    studio, clips = StudioSource(), ClipCache()
    try:
        for line in requests:
            try:
                reply = answer(studio, json.loads(line), clips)
            except (ValueError, KeyError, TypeError) as exc:  # a request the robot refuses (e.g. an unknown object)
                reply = {"ok": False, "invalid": True, "error": str(exc)}
            except Exception as exc:  # noqa: BLE001 - reported to the server, which logs it and works it out itself
                log.exception("working an execution out failed")
                reply = {"ok": False, "invalid": False, "error": f"{type(exc).__name__}: {exc}"}
            replies.write(json.dumps(reply) + "\n")
            replies.flush()
    finally:
        studio.close()


def main() -> None:
    """Answer on the real stdout; anything else printed (viser's banner) goes to stderr."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the server, which closes our stdin
    # Background work: the server's requests (a placement's physics among them) come first on a busy host.
    os.nice(WORKER_NICENESS)
    logging.basicConfig(level=logging.WARNING, format="robot worker %(process)d: %(levelname)s %(message)s")
    replies = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    serve(sys.stdin, replies)


if __name__ == "__main__":
    main()
