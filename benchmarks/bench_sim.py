"""Benchmark the per-participant scene: frames per second that websocket clients see while N robots
move at the same moment in one process, CPU when idle, and memory per session (medians of repeats).

Clients run in a separate process (so decoding does not compete with the server for the GIL); each
speaks viser's websocket protocol like a browser and counts the messages carrying pose updates.

    .venv/bin/python benchmarks/bench_sim.py                 # N = 1, 8, 20; 3 repeats
    .venv/bin/python benchmarks/bench_sim.py --sessions 8 --repeats 1
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import os
import statistics
import time

import numpy as np

POSE_MESSAGES = {"SetPositionMessage", "SetOrientationMessage"}
CAMERA = {
    "type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [1.75, 0.0, 1.35], "fov": 0.8,
    "near": 0.01, "far": 100.0, "image_height": 400, "image_width": 640, "look_at": [0.3, 0.0, 0.4],
    "up_direction": [0.0, 0.0, 1.0],
}


def _watch(ports: list[int], ready: mp.Event, stop: mp.Event, results: mp.Queue) -> None:
    """Client process: connect to every port, timestamp each websocket message that moves a body."""
    import msgspec
    import viser
    import websockets
    import zstandard

    async def client(port: int, stamps: list[float]) -> None:
        url = f"ws://127.0.0.1:{port}"
        async with websockets.connect(url, subprotocols=[f"viser-v{viser.__version__}"], max_size=None) as ws:
            decompress = zstandard.ZstdDecompressor()
            # viser counts a connection as a client once it reports its camera, as a browser does.
            await ws.send(msgspec.msgpack.encode(CAMERA))
            connected.append(port)
            while not stop.is_set():
                try:
                    raw = await asyncio.wait_for(ws.recv(), 0.2)
                except asyncio.TimeoutError:
                    continue
                size, packed = int.from_bytes(raw[:8], "little"), int.from_bytes(raw[8:16], "little")
                inner = msgspec.msgpack.decode(decompress.decompress(raw[16 : 16 + packed], max_output_size=size))
                if any(m.get("type") in POSE_MESSAGES for m in inner["messages"]):
                    stamps.append(time.time())

    async def main() -> list[list[float]]:
        stamps: list[list[float]] = [[] for _ in ports]
        tasks = [asyncio.create_task(client(p, s)) for p, s in zip(ports, stamps, strict=True)]
        while len(connected) < len(ports):
            await asyncio.sleep(0.05)
        ready.set()
        await asyncio.gather(*tasks)
        return stamps

    connected: list[int] = []
    results.put(asyncio.run(main()))


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _naive_ms_per_frame(frames: int = 150) -> float:
    """The naive loop: step physics live for each 1/30 s frame and set every body pose."""
    import mujoco

    from tableteach.sim.physics import MujocoWorld
    from tableteach.sim.view import SceneView

    world = MujocoWorld(seed=0)
    view = SceneView(world.model)
    steps = round((1 / 30) / world.model.opt.timestep)
    try:
        started = time.perf_counter()
        for i in range(frames):
            world.data.ctrl[world.layout.arm_ctrl[0]] = 0.5 * np.sin(i / 10)
            mujoco.mj_step(world.model, world.data, steps)
            poses = world.body_poses()
            nodes = view._mirror.frames  # the view's viser frames, driven directly as naive code would
            for name, pose in zip(world.bodies, poses, strict=True):
                nodes[name].position = pose[:3] + 1e-3 * (i % 2)  # force a send, as naive code does
                nodes[name].wxyz = pose[3:]
        return (time.perf_counter() - started) / frames * 1000
    finally:
        view.close()
        world.close()


def run_once(n: int) -> dict[str, float]:
    """N sessions with one client each place an object at the same moment; measure what clients see."""
    from tableteach.sim.session import SceneSession

    rss_before = _rss_mib()
    sessions = [SceneSession(seed=i, view=True) for i in range(n)]  # replays in real time once watched
    rss_per_session = (_rss_mib() - rss_before) / n
    ctx = mp.get_context("spawn")
    ready, stop, results = ctx.Event(), ctx.Event(), ctx.Queue()
    watcher = ctx.Process(target=_watch, args=([s.view.port for s in sessions], ready, stop, results))
    watcher.start()
    try:
        if not ready.wait(60):
            raise RuntimeError("clients did not connect within 60 s")
        deadline = time.monotonic() + 60
        while any(s.view.client_count == 0 for s in sessions):
            if time.monotonic() > deadline:
                raise RuntimeError("viser did not register every client within 60 s")
            time.sleep(0.05)
        time.sleep(2.0)  # let the initial scene messages drain

        cpu0, idle0 = time.process_time(), time.perf_counter()
        time.sleep(3.0)
        idle_cpu = (time.process_time() - cpu0) / (time.perf_counter() - idle0)

        t_start, cpu0 = time.time(), time.process_time()
        for s in sessions:
            s.run(["dinner_plate"])
        for s in sessions:
            s.wait(timeout=300)
        wall, cpu = time.time() - t_start, time.process_time() - cpu0
        sim_duration = sessions[0].recording.duration
        time.sleep(0.5)
    finally:
        stop.set()
        stamps = results.get(timeout=60)
        watcher.join(10)
        for s in sessions:
            s.close()

    fps, latency, frames = [], [], 0
    for st in stamps:
        st = [t for t in st if t >= t_start]
        frames += len(st)
        fps.append((len(st) - 1) / (st[-1] - st[0]))
        latency.append(st[0] - t_start)
    return {
        "fps_median": statistics.median(fps),
        "fps_min": min(fps),
        "start_latency_s": statistics.median(latency),
        "slowdown": wall / sim_duration,
        "cpu_cores_busy": cpu / wall,
        "ms_per_session_frame": cpu * 1000 / frames,
        "idle_cpu_percent": 100 * idle_cpu,
        "rss_mib_per_session": rss_per_session,
    }


def main() -> None:
    """Print medians over repeats for each N."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, nargs="+", default=[1, 8, 20])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"naive loop (live physics + every pose every frame): {_naive_ms_per_frame():.2f} ms per session-frame")
    header = ["N", "fps_median", "fps_min", "start_latency_s", "slowdown", "cpu_cores_busy",
              "ms_per_session_frame", "idle_cpu_percent", "rss_mib_per_session"]
    print(" ".join(f"{h:>20}" if i else f"{h:>3}" for i, h in enumerate(header)))
    for n in args.sessions:
        runs = [run_once(n) for _ in range(args.repeats)]
        row = [statistics.median(r[h] for r in runs) for h in header[1:]]
        print(f"{n:>3} " + " ".join(f"{v:>20.2f}" for v in row), flush=True)


if __name__ == "__main__":
    main()
