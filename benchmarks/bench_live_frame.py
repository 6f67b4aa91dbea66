"""CPU of showing one placement live on the server, per browser watching: the motion sent once (the client scene's
play(), sim/motion_message.py) against the 30 frames a second it replaced (set_poses per frame), each with viser's
serialisation and compression of what was queued.

    .venv/bin/python benchmarks/bench_live_frame.py [--repeats 20]

Replays a placement of the bowl (the MuJoCo world as the robot simulates it) through a browser's ClientScene
(sim/client_scene.py, as the view hub makes it), with the messages stamped with the browser's owner and collected
instead of sent, then serialises them as viser's websocket thread does (each message's dict, one msgpack per
window, zstd level 1). Each repeat builds a new scene and a new compressor: nothing is reused between repeats.
Prints the medians over the repeats in microseconds per placement, the bytes on the wire and the ratio.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    """Print the medians."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    import msgspec
    import zstandard

    from backend.sim.client_scene import ClientScene, SceneTemplate
    from backend.sim.physics import MujocoWorld

    world = MujocoWorld(seed=0)
    start = len(world.recording) - 1
    world.place("bowl")
    segment = world.recording.since(start)
    template = SceneTemplate(world.model)
    times = segment.times - segment.times[0]

    def wire(windows: list[list[Any]]) -> int:
        compressor = zstandard.ZstdCompressor(level=1)
        size = 0
        for messages in windows:
            buffers: list[memoryview] = []
            inner = msgspec.msgpack.encode({"messages": tuple(m.as_serializable_dict(buffers) for m in messages)})
            size += len(compressor.compress(inner))
        return size

    results: dict[str, list[tuple[float, int, int]]] = {"sent once": [], "streamed": []}
    for _ in range(args.repeats):
        for how in results:
            sink: list[Any] = []

            def stamped(message: Any, sink: list[Any] = sink) -> None:
                message.owner = "1"  # as the client's scene API stamps it
                sink.append(message)

            scene = ClientScene(template, stamped)
            scene.set_poses(segment.bodies, segment.poses[0])
            sink.clear()
            started = time.process_time()
            if how == "sent once":
                scene.play(segment.bodies, times, segment.poses)
                windows = [sink[:]]
            else:
                windows = []
                for frame in range(len(segment)):
                    scene.set_poses(segment.bodies, segment.poses[frame])
                    windows.append(sink[:])
                    sink.clear()
            size = wire(windows)
            results[how].append((1e6 * (time.process_time() - started), size, sum(len(w) for w in windows)))
    print(f"a placement of {len(segment)} frames ({segment.duration:.1f} s), per browser watching; "
          f"medians of {args.repeats}")
    for how, runs in results.items():
        print(f"{how}: {statistics.median(r[0] for r in runs):.0f} us of CPU, "
              f"{statistics.median(r[1] for r in runs) / 1024:.1f} KiB on the wire, {runs[0][2]} messages")
    ratio = statistics.median(r[0] for r in results["streamed"]) / statistics.median(r[0] for r in results["sent once"])
    print(f"sending the motion once costs 1/{ratio:.0f} of streaming it")


if __name__ == "__main__":
    main()
