"""The robot's recorded motions for the browser: the participant's .viser files, which viser's own client plays
(`/p/{token}/viewer/?playbackPath=...`), served by any app process from the recording store."""

from __future__ import annotations

import asyncio
import time
from urllib.parse import quote

from fastapi import APIRouter
from fastapi.responses import FileResponse, PlainTextResponse, Response
from starlette.concurrency import run_in_threadpool

from .. import services
from ..errors import NotAuthenticated
from ..recording_store import RecordingId
from .deps import ContextDep

router = APIRouter(tags=["participant page"])
WAIT_SECONDS = 30.0  # a work_out job takes about a second; by then it has run (or is being retried)
POLL_SECONDS = 0.1


def motion_path(token: str, rid: RecordingId) -> str:
    """The URL path of a participant's recorded step."""
    return f"/p/{token}/motion/task-{rid.task_index}/{rid.step_kind}-{rid.step_index}.viser"


def playback_url(token: str, rid: RecordingId, replays: int = 0) -> str:
    """The viewer page playing a recorded step instead of connecting to a live view; each "Watch it again" gives
    a new address (`replay=n`), so the page reloads the player, which plays the (cached) file from the start."""
    again = f"&replay={replays}" if replays else ""
    return f"/p/{token}/viewer/?playbackPath={quote(motion_path(token, rid), safe='')}{again}"


@router.get("/p/{token}/motion/task-{task_index}/{step_kind}-{step_index}.viser", include_in_schema=False)
async def motion_file(token: str, task_index: int, step_kind: str, step_index: int, ctx: ContextDep) -> Response:
    """One recorded execution of this participant as a .viser file (cached by the browser: it never changes).

    The page asks for it as soon as the execution starts; while the robot is still working it out (about a
    second) the answer waits for the file, up to WAIT_SECONDS."""
    try:
        participant_uid = await run_in_threadpool(services.participant_uid_of, ctx, token)
        rid = RecordingId(participant_uid, task_index, step_kind, step_index)
    except NotAuthenticated:
        return PlainTextResponse("No participant has this link.", status_code=404)
    except ValueError as exc:
        return PlainTextResponse(f"No such recording: {exc}", status_code=404)
    path = ctx.store.playable(rid)
    deadline = time.monotonic() + WAIT_SECONDS
    # The local file, or one this host fetches from the store every host reaches (TABLETEACH_RECORDING_STORE).
    while not (ready := await run_in_threadpool(ctx.store.ready, rid)) and time.monotonic() < deadline:
        await asyncio.sleep(POLL_SECONDS)
    if not ready:
        return PlainTextResponse(f"No recording of {step_kind} {step_index + 1} in task {task_index + 1} yet.",
                                 status_code=404)
    return FileResponse(path, media_type="application/octet-stream",
                        headers={"Cache-Control": "private, max-age=86400", "Referrer-Policy": "no-referrer"})
