"""The robot's recorded motions for the browser: the participant's .viser files, which viser's own client plays
(`/p/{token}/viewer/?playbackPath=...`), served by any app process from the recording store."""

from __future__ import annotations

from urllib.parse import quote

from fastapi import APIRouter
from fastapi.responses import FileResponse, PlainTextResponse, Response

from .. import services
from ..errors import NotAuthenticated
from ..sim.motion_file import viser_path
from ..sim.recordings import RecordingId
from .deps import ContextDep

router = APIRouter(tags=["participant page"])
STEP_KINDS_PATTERN = r"^(practice|demonstration|query|test)$"


def motion_path(token: str, rid: RecordingId) -> str:
    """The URL path of a participant's recorded step."""
    return f"/p/{token}/motion/task-{rid.task_index}/{rid.step_kind}-{rid.step_index}.viser"


def playback_url(token: str, rid: RecordingId) -> str:
    """The viewer page playing a recorded step instead of connecting to a live view."""
    return f"/p/{token}/viewer/?playbackPath={quote(motion_path(token, rid), safe='')}"


@router.get("/p/{token}/motion/task-{task_index}/{step_kind}-{step_index}.viser", include_in_schema=False)
def motion_file(token: str, task_index: int, step_kind: str, step_index: int, ctx: ContextDep) -> Response:
    """One recorded execution of this participant as a .viser file (cached by the browser: it never changes)."""
    try:
        participant_id = services.participant_id_of(ctx, token)
        rid = RecordingId(participant_id, task_index, step_kind, step_index)
    except NotAuthenticated:
        return PlainTextResponse("No participant has this link.", status_code=404)
    except ValueError as exc:
        return PlainTextResponse(f"No such recording: {exc}", status_code=404)
    path = viser_path(ctx.settings.data_dir, rid)
    if not path.is_file():
        return PlainTextResponse(f"No recording of {step_kind} {step_index + 1} in task {task_index + 1} yet.",
                                 status_code=404)
    return FileResponse(path, media_type="application/octet-stream",
                        headers={"Cache-Control": "private, max-age=86400", "Referrer-Policy": "no-referrer"})
