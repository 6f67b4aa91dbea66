"""Server memory and threads with open live 3D views: 0, 50 and 100 participants' views open through the app's
websocket proxy (each reporting a camera, as viser's browser client does), and 30 s after they close.

    python benchmarks/bench_views.py                 # 0, 1, 50, 100 views
    python benchmarks/bench_views.py --views 0,20    # other counts
    python benchmarks/bench_views.py --trace         # also the Python heap (tracemalloc; RSS is then inflated)

Starts `tableteach serve` with the MuJoCo robot on a temporary SQLite database (loopback only), reads the
server's VmRSS and thread count from /proc, and prints one line per count and the cost per idle view. The views are
idle (no robot moves) and are opened by a websockets client, not a browser: what is measured is the server's side
of each view (the browser's websocket in uvicorn, the proxy's websocket to viser, viser's connection and client,
and the view's own scene state). The server runs under benchmarks/server_probe.py, which says on request how many
views, viser clients and connections it holds and which threads it runs: after the views close, those counts
show when their state was let go (the resident size does not fall: CPython and malloc keep freed memory for reuse).
Target (issue 18): memory and threads flat in the number of views, under 0.2 MB per idle view, and what a view
held released within 30 s of its page closing.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
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


def probe(server: subprocess.Popen, path: Path) -> dict:
    """What the server's views hold now (benchmarks/server_probe.py answers SIGUSR1 with a JSON file)."""
    path.unlink(missing_ok=True)
    server.send_signal(signal.SIGUSR1)
    deadline = time.monotonic() + 60
    while not path.exists():
        if time.monotonic() > deadline:
            raise RuntimeError("the server's probe never answered")
        time.sleep(0.05)
    return json.loads(path.read_text())


def held(state: dict) -> str:
    """The probe's counts as one line."""
    heap = "" if state["python_heap"] is None else f", Python heap {state['python_heap'] / 2**20:.1f} MiB"
    return (f"hub views {state['views']}, viser clients {state['viser_clients']}, "
            f"viser connections {state['connections']}{heap}")


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
    parser.add_argument("--trace", action="store_true", help="trace the server's Python allocations (tracemalloc) "
                        "and report its Python heap per view; the resident sizes are then larger than without")
    args = parser.parse_args(argv)
    counts = sorted({int(x) for x in args.views.split(",")})
    with tempfile.TemporaryDirectory(prefix="tableteach-views-") as tmp:
        port = free_port()
        answer = Path(tmp) / "probe.json"
        env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": TOKEN, "TABLETEACH_ROBOT": "mujoco",
               "TABLETEACH_DATA_DIR": f"{tmp}/data", "TABLETEACH_JOINS_PER_ADDRESS": "100000",
               "TABLETEACH_BENCH_PROBE": str(answer), "TABLETEACH_BENCH_TRACE": "1" if args.trace else "0"}
        db = f"sqlite:///{tmp}/views.db"
        from tableteach.db.migrate import upgrade_head

        upgrade_head(db)
        server = subprocess.Popen([sys.executable, str(Path(__file__).with_name("server_probe.py")), "serve",
                                   "--port", str(port), "--database-url", db],
                                  env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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
                state = probe(server, answer)
                rows.append((n, rss, threads, state["python_heap"]))
                print(f"{n:4d} open views: server RSS {rss:7.1f} MiB, {threads} threads", flush=True)
                print(f"      in the server: {held(state)}", flush=True)
            closed = time.monotonic()
            for ws in views:
                loop.run_until_complete(ws.close())  # type: ignore[attr-defined]
            state = probe(server, answer)
            while any(state[k] for k in ("views", "viser_clients", "connections")) and time.monotonic() - closed < 30:
                time.sleep(0.5)
                state = probe(server, answer)
            gone = time.monotonic() - closed
            if any(state[k] for k in ("views", "viser_clients", "connections")):
                print(f"  views still held 30 s after closing them: {held(state)}", flush=True)
            else:
                print(f"  every view's state let go {gone:.1f} s after closing them (closing included): {held(state)}",
                      flush=True)
            time.sleep(max(0.0, 30 - (time.monotonic() - closed)))
            rss, threads = proc_status(server.pid)
            state = probe(server, answer)
            print(f"  30 s after closing them: server RSS {rss:7.1f} MiB, {threads} threads", flush=True)
            print(f"      in the server: {held(state)}", flush=True)
            print("      threads: " + ", ".join(f"{name} {k}" for name, k in state["threads"].items()), flush=True)
            base = 1 if len(rows) > 2 and counts[0] == 0 else 0  # from the first count with the server running
            for (n0, rss0, _t0, _h0), (n1, rss1, _t1, _h1) in zip(rows[base:-1], rows[base + 1:], strict=True):
                print(f"  from {n0} to {n1} views: {(rss1 - rss0) / (n1 - n0) * 1024:.0f} KiB a view")
            first, last = rows[base], rows[-1]
            n = counts[-1] - counts[base]
            if n > 0:
                print(f"per idle view: {(last[1] - first[1]) / n * 1024:.0f} KiB and "
                      f"{(last[2] - first[2]) / n:.2f} threads (target < 200 KiB, flat)")
                if first[3] is not None and last[3] is not None:
                    print(f"Python heap per idle view (tracemalloc): {(last[3] - first[3]) / n / 1024:.0f} KiB; "
                          f"30 s after closing {(state['python_heap'] - first[3]) / 1024:+.0f} KiB against "
                          f"{counts[base]} open views")
        finally:
            server.terminate()
            try:
                server.wait(timeout=20)
            except subprocess.TimeoutExpired:
                server.kill()
    return 0


if __name__ == "__main__":
    sys.exit(main())
