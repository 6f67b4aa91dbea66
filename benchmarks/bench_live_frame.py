"""CPU of one live 3D-view frame on the server: a browser's scene's pose comparison and queueing, and viser's
serialisation of the queued messages, per browser watching a moving table.

    .venv/bin/python benchmarks/bench_live_frame.py [--repeats 20]

Replays a recorded placement (the bowl, the MuJoCo world as the robot simulates it) through a browser's ClientScene
(sim/client_scene.py, as the view hub makes it), frame by frame as the animator shows it, with the messages
stamped with the browser's owner and collected instead of sent; then
serialises them as viser's websocket thread does (each message's dict, one msgpack per frame). Prints the
medians over the repeats in microseconds per frame, and the messages per frame. The live view streams 30 frames
a second to each browser watching a moving table, so 1,000 us per frame is 3% of a core per such browser.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    """Print the medians."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    import msgspec

    from backend.sim.client_scene import ClientScene, SceneTemplate
    from backend.sim.physics import MujocoWorld

    world = MujocoWorld(seed=0)
    world.place("bowl")
    rec = world.recording
    template = SceneTemplate(world.model)
    mirror_us, serialise_us, per_frame = [], [], []
    for _ in range(args.repeats):
        sink: list[object] = []

        def stamped(message: object, sink: list[object] = sink) -> None:
            message.owner = "1"  # type: ignore[attr-defined]  # as the client's scene API stamps it
            sink.append(message)

        scene = ClientScene(template, stamped)
        sink.clear()
        frames: list[list[object]] = []
        started = time.process_time()
        for frame in range(len(rec)):
            scene.set_poses(rec.bodies, rec.poses[frame])
            frames.append(sink[:])
            sink.clear()
        mirror_us.append(1e6 * (time.process_time() - started) / len(rec))
        started = time.process_time()
        for messages in frames:
            buffers: list[memoryview] = []
            msgspec.msgpack.encode({"messages": tuple(m.as_serializable_dict(buffers) for m in messages)})  # type: ignore[attr-defined]
        serialise_us.append(1e6 * (time.process_time() - started) / len(rec))
        per_frame.append(sum(len(m) for m in frames) / len(frames))
    print(f"{len(rec)} frames of a placement, {statistics.median(per_frame):.1f} pose messages per frame")
    print(f"client scene (compare and queue): median {statistics.median(mirror_us):.1f} us per frame")
    print(f"serialise (viser's websocket thread's part): median {statistics.median(serialise_us):.1f} us per frame")


if __name__ == "__main__":
    main()
