"""Server memory and threads with open live 3D views: 0, 50 and 100 participants' views open through the app's
websocket proxy (each reporting a camera, as viser's browser client does), and 30 s after they close.

    python benchmarks/bench_views.py                 # 0, 1, 50, 100 views
    python benchmarks/bench_views.py --views 0,20    # other counts

Starts `tableteach serve` with the MuJoCo robot on a temporary SQLite database (loopback only), reads the
server's VmRSS and thread count from /proc, and prints one line per count and the cost per idle view.
Target (issue 18): memory and threads flat in the number of views, under 0.2 MB per idle view, and what a view
held released within 30 s of its page closing.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import msgpack
import websockets

TOKEN = "bench-views-experimenter-token-012345"
STUDY = {"name": "views", "tasks": [{"key": "task1"}], "conditions": ["active"], "n_practice": 0,
         "n_demonstrations": 2, "n_queries": 1, "n_tests": 0, "questionnaire": []}
CAMERA = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0], "position": [2.0, 0.0, 1.5],
          "image_height": 600, "image_width": 800, "fov": 0.9, "near": 0.01, "far": 100.0,
          "look_at": [0.0, 0.0, 0.4], "up_direction": [0.0, 0.0, 1.0]}


def free_port() -> int:
    """A TCP port that was free a moment ago on 127.0.0.1."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def proc_status(pid: int) -> tuple[float, int]:
    """A process's resident memory (MiB) and thread count, from /proc."""
    rss, threads = 0.0, 0
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            rss = int(line.split()[1]) / 1024
        elif line.startswith("Threads:"):
            threads = int(line.split()[1])
    return rss, threads


def participants(url: str, n: int) -> list[str]:
    """n participants at their first demonstration; their tokens."""
    exp = {"Authorization": f"Bearer {TOKEN}"}
    study = httpx.post(f"{url}/api/v1/studies", json=STUDY, headers=exp, timeout=30).json()["id"]
    httpx.post(f"{url}/api/v1/studies/{study}/open", headers=exp, timeout=30).raise_for_status()
    tokens = []
    for _ in range(n):
        joined = httpx.post(f"{url}/api/v1/studies/{study}/join", json={}, timeout=30).json()
        me = {"Authorization": f"Bearer {joined['token']}"}
        version = joined["state"]["consent"]["version"]
        httpx.post(f"{url}/api/v1/me/consent", json={"consent_version": version, "agree": True}, headers=me,
                   timeout=30).raise_for_status()
        httpx.post(f"{url}/api/v1/me/instructions", headers=me, timeout=30).raise_for_status()
        tokens.append(joined["token"])
    return tokens


async def open_views(port: int, tokens: list[str]) -> list[object]:
    """A live view per token through the app's proxy, each having reported its camera."""
    import viser

    views = []
    for token in tokens:
        ws = await websockets.connect(f"ws://127.0.0.1:{port}/p/{token}/viewer",
                                      subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
                                      origin=f"http://127.0.0.1:{port}", max_size=None)  # type: ignore[arg-type]
        await ws.recv()
        await ws.send(msgpack.packb(CAMERA))
        views.append(ws)
    return views


async def drain(views: list[object], seconds: float) -> None:
    """Read what the server sends the open views for a while (as browsers do), so nothing backs up."""
    async def read(ws: object) -> None:
        try:
            while True:
                await asyncio.wait_for(ws.recv(), seconds)  # type: ignore[attr-defined]
        except (asyncio.TimeoutError, websockets.ConnectionClosed):
            return

    await asyncio.wait_for(asyncio.gather(*(read(ws) for ws in views)), seconds + 5)


def main(argv: list[str] | None = None) -> int:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--views", default="0,1,50,100", help="comma-separated counts of open views (the first view "
                        "starts the process's one viser server: the cost per view is read from the second count on)")
    parser.add_argument("--settle-seconds", type=float, default=3.0, help="wait after opening before reading /proc")
    args = parser.parse_args(argv)
    counts = sorted({int(x) for x in args.views.split(",")})
    with tempfile.TemporaryDirectory(prefix="tableteach-views-") as tmp:
        port = free_port()
        env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": TOKEN, "TABLETEACH_ROBOT": "mujoco",
               "TABLETEACH_DATA_DIR": f"{tmp}/data", "TABLETEACH_JOINS_PER_ADDRESS": "100000"}
        db = f"sqlite:///{tmp}/views.db"
        from tableteach.db.migrate import upgrade_head

        upgrade_head(db)
        server = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--port", str(port),
                                   "--database-url", db], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            url = f"http://127.0.0.1:{port}"
            deadline = time.monotonic() + 60
            while True:
                try:
                    if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline:
                    raise RuntimeError("the server never answered /healthz")
                time.sleep(0.2)
            tokens = participants(url, max(counts))
            loop = asyncio.new_event_loop()
            rows = []
            views: list[object] = []
            for n in counts:
                if n > len(views):
                    views += loop.run_until_complete(open_views(port, tokens[len(views):n]))
                loop.run_until_complete(drain(views, args.settle_seconds))
                rss, threads = proc_status(server.pid)
                rows.append((f"{n} open views", rss, threads))
                print(f"{n:4d} open views: server RSS {rss:7.1f} MiB, {threads} threads", flush=True)
            for ws in views:
                loop.run_until_complete(ws.close())  # type: ignore[attr-defined]
            time.sleep(30)
            rss, threads = proc_status(server.pid)
            print(f"  30 s after closing them: server RSS {rss:7.1f} MiB, {threads} threads", flush=True)
            base = 1 if len(rows) > 2 and counts[0] == 0 else 0  # from the first count with the server running
            first, last = rows[base], rows[-1]
            n = counts[-1] - counts[base]
            if n > 0:
                print(f"per idle view: {(last[1] - first[1]) / n * 1024:.0f} KiB and "
                      f"{(last[2] - first[2]) / n:.2f} threads (target < 200 KiB, flat)")
        finally:
            server.terminate()
            try:
                server.wait(timeout=20)
            except subprocess.TimeoutExpired:
                server.kill()
    return 0


if __name__ == "__main__":
    sys.exit(main())
