"""Attack script: runs the attacks of a public study link against fresh local servers and prints what held.

Each attack gets a fresh `tableteach serve` on a temp SQLite file, on a free loopback port (nothing else is
contacted), and is bounded in count and time. While it runs, a probe opens a new connection to /healthz
every 50 ms and the script reports its latency (median, p99) and failures.

- slow headers: --slow connections (default 1000) send part of their headers and stall, plus 100 bodies that
  stall; how many the server closed and within how long (the deadline is TABLETEACH_HEADER_TIMEOUT_SECONDS).
- join flood: --joins joins from one address at once (the per-address limit), then a study with 20 places
  flooded on a server without that limit; joins accepted, refused (429, 409) and the database's growth.
- event streams: 1000 streams for one participant token (at most two stay open); 50 participants place
  objects for --seconds, one action every --pause seconds (default 1: 50 actions a second), without streams
  (the machine's baseline), then 500 streams (two per participant) are opened and 50 of their participants
  place objects as long (judged: /healthz p99 under 100 ms); then, for reference and not judged, 50 others
  without a pause (the server saturated); streams accepted and still open, events received, and the 503
  beyond the process cap.
- wrong keys: --wrong wrong experimenter keys from one address with the right key every 10th request.
- deep formula: custom tasks whose ground truth nests 1,990 negations or 996 parentheses.

    .venv/bin/python benchmarks/abuse.py            # about two minutes
    .venv/bin/python benchmarks/abuse.py --scale 0.2
"""

from __future__ import annotations

import argparse
import asyncio
import os
import secrets
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx

TOKEN = "abuse-" + secrets.token_urlsafe(32)
TARGET_HOLD_MS = 200.0  # /healthz while slow connections are held
TARGET_STREAMS_P99_MS = 100.0  # /healthz while streams are open and placements go on
# 50 participants acting once a second are 50 actions a second: three times bench_scale's people (one action per
# 3 s) for 50, or 150 such people on one process, five times the 30 per process the README plans for.
PLACEMENT_PAUSE = 1.0
FLAT_OUT_PAUSE = 0.1  # the stress figure: the server saturated, every action queued behind others


# ------------------------------------------------------------------------------------------------ the server


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """A fresh `tableteach serve` on a temp SQLite file and a free loopback port."""

    def __init__(self, folder: Path, **env: str) -> None:
        self.folder = folder
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.db = folder / "abuse.db"
        full_env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": TOKEN, "TABLETEACH_DATA_DIR": str(folder / "data"),
                    **env}
        full_env.pop("TABLETEACH_DEV_MODE", None)
        self.log = folder / "server.log"
        from tableteach.db.migrate import upgrade_head

        upgrade_head(f"sqlite:///{self.db}")  # serve refuses a database it would have to migrate
        with open(self.log, "wb") as log:
            self.proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--port", str(self.port),
                                          "--database-url", f"sqlite:///{self.db}"], env=full_env,
                                         stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 60
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"the server exited with {self.proc.returncode}: {self.log.read_text()[-500:]}")
            try:
                if httpx.get(f"{self.url}/healthz", timeout=1).status_code == 200:
                    return
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("the server did not answer /healthz within 60 s")
            time.sleep(0.1)

    def stop(self) -> None:
        if self.proc.poll() is not None:
            say(f"the server had exited with {self.proc.returncode}: {self.log.read_text()[-2000:]}")
        warnings = [line for line in self.log.read_text().splitlines() if "ERROR" in line or "Traceback" in line]
        if warnings:
            say(f"the server logged {len(warnings)} error line(s), the first: {warnings[0][:200]}")
        self.proc.terminate()
        try:
            self.proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)

    def open_study(self, **extra: Any) -> str:
        headers = {"Authorization": f"Bearer {TOKEN}"}
        spec = {"name": "abuse", "tasks": [{"key": "task1"}], "conditions": ["active", "batch"], **extra}
        r = httpx.post(f"{self.url}/api/v1/studies", json=spec, headers=headers, timeout=30)
        r.raise_for_status()
        study = r.json()["id"]
        httpx.post(f"{self.url}/api/v1/studies/{study}/open", headers=headers, timeout=30).raise_for_status()
        return study


def probe_once(port: int) -> float | None:
    """Milliseconds for one /healthz on a new connection (None: refused, failed or over 5 s)."""
    started = time.perf_counter()
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
            sock.sendall(b"GET /healthz HTTP/1.0\r\nHost: probe\r\n\r\n")
            answer = b""
            while chunk := sock.recv(4096):
                answer += chunk
    except OSError:
        return None
    return (time.perf_counter() - started) * 1000 if answer.startswith(b"HTTP/1.1 200") else None


def run_probe(port: int) -> None:
    """The probe process: one line per /healthz (milliseconds, or "fail") every 50 ms until stdin closes."""
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    print("ready", flush=True)
    while not stop.is_set():
        ms = probe_once(port)
        print("fail" if ms is None else f"{ms:.3f}", flush=True)
        stop.wait(0.05)


class HealthProbe:
    """/healthz on a new connection every 50 ms, from a process of its own (the attack's client loop and GIL
    do not delay it): latencies (ms) and failures."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.latencies: list[float] = []
        self.failures = 0
        self._proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> HealthProbe:
        self._proc = subprocess.Popen([sys.executable, __file__, "--probe-port", str(self.port)],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self._proc.stdout is not None and self._proc.stdout.readline().strip() == "ready"
        return self

    def __exit__(self, *_exc: object) -> None:
        assert self._proc is not None
        out, _ = self._proc.communicate(input="", timeout=30)
        for line in out.split():
            if line == "fail":
                self.failures += 1
            else:
                self.latencies.append(float(line))

    def summary(self) -> str:
        if not self.latencies:
            return f"/healthz: no answer ({self.failures} failures)"
        ordered = sorted(self.latencies)
        p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
        return (f"/healthz: {len(ordered)} answers, median {statistics.median(ordered):.1f} ms, p99 {p99:.1f} ms, "
                f"max {ordered[-1]:.1f} ms, {self.failures} failures")

    def p99(self) -> float:
        ordered = sorted(self.latencies) or [float("inf")]
        return ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]


def say(text: str) -> None:
    print(text, flush=True)


# ------------------------------------------------------------------------------------------------- attacks


async def _held_until_closed(port: int, payload: bytes, limit: float) -> float | None:
    """Open a connection, send `payload`, and return when the server closed it (seconds), None if not in `limit`."""
    started = time.monotonic()
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
    except OSError:
        return -1.0  # refused: counted apart
    try:
        writer.write(payload)
        await writer.drain()
        try:
            while await asyncio.wait_for(reader.read(4096), limit - (time.monotonic() - started)):
                pass
        except asyncio.TimeoutError:
            return None
        except ConnectionError:
            pass
        return time.monotonic() - started
    finally:
        writer.close()


def attack_slow_headers(folder: Path, n: int) -> bool:
    say(f"\n== slow headers: {n} connections that never finish their headers, 100 stalled bodies")
    server = Server(folder)
    try:
        limit = 25.0
        slow = b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: "
        stalled = b"POST /api/v1/studies/x/join HTTP/1.1\r\nHost: x\r\nContent-Length: 1000\r\n\r\n{"

        async def run() -> tuple[list[float | None], list[float | None], int]:
            tasks = [asyncio.ensure_future(_held_until_closed(server.port, slow, limit)) for _ in range(n)]
            tasks += [asyncio.ensure_future(_held_until_closed(server.port, stalled, limit)) for _ in range(100)]
            await asyncio.sleep(2.0)
            open_now = sum(not t.done() for t in tasks)
            results = await asyncio.gather(*tasks)
            return list(results[:n]), list(results[n:]), open_now

        with HealthProbe(server.port) as probe:
            headers, bodies, open_after_2s = asyncio.run(run())
        for name, results in (("slow headers", headers), ("stalled bodies", bodies)):
            closed = [r for r in results if r is not None and r >= 0]
            refused = sum(1 for r in results if r is not None and r < 0)
            say(f"{name}: {len(results)} opened, {refused} refused, {len(closed)} closed by the server "
                f"(after {min(closed, default=0):.1f}-{max(closed, default=0):.1f} s), "
                f"{sum(r is None for r in results)} still open after {limit:.0f} s")
        say(f"connections held 2 s in: {open_after_2s}")
        say(probe.summary())
        ok = all(r is not None for r in headers + bodies) and probe.p99() < TARGET_HOLD_MS and probe.failures == 0
        say(f"held: {'yes' if ok else 'NO'} (every connection closed, /healthz p99 under {TARGET_HOLD_MS:.0f} ms)")
        return ok
    finally:
        server.stop()


async def _joins(url: str, study: str, n: int) -> Counter[int]:
    limits = httpx.Limits(max_connections=50)
    async with httpx.AsyncClient(base_url=url, timeout=30, limits=limits) as client:
        async def one(i: int) -> int:
            r = await client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": f"flood-{i}"})
            return r.status_code

        return Counter(await asyncio.gather(*(one(i) for i in range(n))))


def attack_join_flood(folder: Path, n: int) -> bool:
    say(f"\n== join flood: {n} joins from one address at once")
    server = Server(folder / "rate")
    try:
        study = server.open_study()
        before = server.db.stat().st_size
        with HealthProbe(server.port) as probe:
            started = time.monotonic()
            statuses = asyncio.run(_joins(server.url, study, n))
            seconds = time.monotonic() - started
        say(f"answers in {seconds:.1f} s: {dict(sorted(statuses.items()))} (201 joined, 429 limited per address)")
        say(f"database: {before / 1e6:.2f} MB before, {server.db.stat().st_size / 1e6:.2f} MB after")
        say(probe.summary())
        limited_ok = statuses[201] <= 30 and statuses[429] == n - statuses[201]
    finally:
        server.stop()
    say(f"-- {n} joins of a study with 20 places, the per-address limit lifted")
    server = Server(folder / "places", TABLETEACH_JOINS_PER_ADDRESS="100000")
    try:
        study = server.open_study(places=20)
        with HealthProbe(server.port) as probe:
            statuses = asyncio.run(_joins(server.url, study, n))
        say(f"answers: {dict(sorted(statuses.items()))} (201 joined, 409 this study is full)")
        page = httpx.get(f"{server.url}/study/{study}/join?PROLIFIC_PID=late", timeout=30)
        say(f"the join link now: {page.status_code}, "
            f"{'a page saying the study is full' if 'This study is full' in page.text else page.text[:80]}")
        say(probe.summary())
        places_ok = statuses[201] == 20 and statuses[409] == n - 20
    finally:
        server.stop()
    ok = limited_ok and places_ok
    say(f"held: {'yes' if ok else 'NO'} (at most 30 joins a minute per address; no join past the places)")
    return ok


async def _settled(readers: list[StreamReader], limit: float = 60.0) -> None:
    """Wait until every stream has its answer (status), at most `limit` seconds."""
    deadline = time.monotonic() + limit
    while any(r.status == 0 for r in readers) and time.monotonic() < deadline:
        await asyncio.sleep(0.1)


class StreamReader:
    """One raw event stream: its status, and how many change and superseded events it read."""

    def __init__(self) -> None:
        self.status = 0
        self.changes = 0
        self.superseded = False
        self.closed = False

    async def run(self, port: int, token: str, stop: asyncio.Event) -> None:
        try:
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
        except OSError:
            self.status = -1
            return
        try:
            writer.write(f"GET /p/{token}/events HTTP/1.0\r\nHost: x\r\n\r\n".encode())
            head = await reader.readuntil(b"\r\n\r\n")
            self.status = int(head.split(b" ")[1])
            buffer = b""
            while not stop.is_set():
                read = asyncio.ensure_future(reader.read(65536))
                halt = asyncio.ensure_future(stop.wait())
                await asyncio.wait({read, halt}, return_when=asyncio.FIRST_COMPLETED)
                halt.cancel()
                if not read.done():
                    read.cancel()
                    break
                chunk = read.result()
                if not chunk:
                    self.closed = True
                    break
                buffer += chunk
                *events, buffer = buffer.split(b"\n\n")
                self.changes += sum(b"event: change" in e for e in events)
                self.superseded = self.superseded or any(b"event: superseded" in e for e in events)
        except (OSError, asyncio.IncompleteReadError):
            self.closed = True
        finally:
            writer.close()


async def _participant(client: httpx.AsyncClient, study: str, i: int) -> str:
    r = await client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": f"p-{i}"})
    r.raise_for_status()
    token, state = r.json()["token"], r.json()["state"]
    h = {"Authorization": f"Bearer {token}"}
    (await client.post("/api/v1/me/consent", json={"agree": True, "consent_version": state["consent"]["version"]},
                       headers=h)).raise_for_status()
    (await client.post("/api/v1/me/instructions", headers=h)).raise_for_status()
    return token


async def _place_for(client: httpx.AsyncClient, token: str, until: float, counts: Counter[str],
                     pause: float) -> None:
    """Place objects and finish demonstrations, one action then `pause` seconds, until `until`."""
    h = {"Authorization": f"Bearer {token}"}
    objects = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]
    i = 0
    while time.monotonic() < until:
        if i % 6 < 5:
            r = await client.post("/api/v1/me/placements", json={"object": objects[i % 6]}, headers=h)
        else:
            r = await client.post("/api/v1/me/demonstration/finish", headers=h)
        counts[str(r.status_code)] += 1
        if r.status_code == 409:
            return  # this participant's demonstrations are over
        i += 1
        await asyncio.sleep(pause)


def attack_event_streams(folder: Path, one_token: int, n_streams: int, seconds: float, pause: float) -> bool:
    n_people = n_streams // 2
    cap = n_streams + 52  # the two of the one token, the participants' and 50 more
    say(f"\n== event streams: {one_token} for one token, then {n_streams} ({n_people} participants x 2) while 50 "
        f"place objects for {seconds:.0f} s; process cap {cap}")
    # The trace robot: the attack is on the event streams, with placements as the work going on beside them. The
    # MuJoCo robot's physics for placements nobody made before, at the 35 a second of 50 participants placing
    # without pause, is several cores of CPU on its own (benchmarks/bench_scale.py measures the robot at a
    # person's pace), and /healthz then waits behind that overload with or without any stream.
    server = Server(folder, TABLETEACH_JOINS_PER_ADDRESS="100000", TABLETEACH_MAX_EVENT_STREAMS=str(cap),
                    TABLETEACH_ROBOT="trace")
    ok = True
    try:
        study = server.open_study(n_practice=0, n_demonstrations=20, n_queries=0, n_tests=0)

        async def run() -> None:
            nonlocal ok
            limits = httpx.Limits(max_connections=60)
            async with httpx.AsyncClient(base_url=server.url, timeout=60, limits=limits) as client:
                tokens = []
                total = n_people + 1 + 100  # the one token's, the participants' and 100 for the cap
                for start in range(0, total, 50):
                    tokens += await asyncio.gather(*(_participant(client, study, i)
                                                     for i in range(start, min(total, start + 50))))
                say(f"{len(tokens)} participants at their first demonstration")
                late, tokens = tokens[n_people + 1:], tokens[:n_people + 1]
                stop = asyncio.Event()
                # One token, many streams: all are answered, the newest two stay open.
                solo = [StreamReader() for _ in range(one_token)]
                solo_tasks = []
                for k in range(0, one_token, 100):
                    solo_tasks += [asyncio.ensure_future(r.run(server.port, tokens[-1], stop)) for r in solo[k:k + 100]]
                    await asyncio.sleep(0.2)
                await _settled(solo)
                await asyncio.sleep(1.0)
                still = sum(not r.closed for r in solo)
                say(f"one token: {sum(r.status == 200 for r in solo)} of {one_token} streams answered 200, "
                    f"{sum(r.superseded for r in solo)} superseded, {still} still open")
                ok = ok and still <= 2
                # The same placements without the streams first: what this machine gives now, for comparison.
                baseline: Counter[str] = Counter()
                with HealthProbe(server.port) as probe:
                    until = time.monotonic() + seconds
                    await asyncio.gather(*(_place_for(client, t, until, baseline, pause) for t in tokens[-50:]))
                say(f"without the streams, placements and finishes ({len(tokens[-50:])} participants, {pause:g} s "
                    f"apart): {dict(baseline)}; {probe.summary()}")
                # Many participants, two streams each, while placements go on.
                readers = [StreamReader() for _ in range(2 * n_people)]
                tasks = []
                for k in range(0, len(readers), 100):
                    tasks += [asyncio.ensure_future(r.run(server.port, tokens[j // 2], stop))
                              for j, r in enumerate(readers[k:k + 100], start=k)]
                    await asyncio.sleep(0.2)
                await _settled(readers)
                say(f"{sum(r.status == 200 for r in readers)} of {len(readers)} streams answered 200, "
                    f"{sum(not r.closed for r in readers)} open")
                counts: Counter[str] = Counter()
                with HealthProbe(server.port) as probe:
                    until = time.monotonic() + seconds
                    await asyncio.gather(*(_place_for(client, t, until, counts, pause) for t in tokens[:50]))
                say(f"with the streams, placements and finishes ({pause:g} s apart): {dict(counts)}; {probe.summary()}")
                say(f"change events read: {sum(r.changes for r in readers)} (streams of the 50 who acted: "
                    f"{sum(r.changes for r in readers[:100])})")
                ok = ok and probe.p99() < TARGET_STREAMS_P99_MS and probe.failures == 0
                # For reference, not judged: the same participants without a pause, the server saturated.
                flat: Counter[str] = Counter()
                with HealthProbe(server.port) as probe:
                    until = time.monotonic() + seconds
                    await asyncio.gather(*(_place_for(client, t, until, flat, FLAT_OUT_PAUSE)
                                           for t in tokens[50:100]))
                say(f"stress (not judged), with the streams, 50 others {FLAT_OUT_PAUSE:g} s apart: {dict(flat)}; "
                    f"{probe.summary()}")
                # Beyond the process cap: 503 with Retry-After.
                extra = [StreamReader() for _ in late]
                extra_tasks = [asyncio.ensure_future(r.run(server.port, token, stop))
                               for r, token in zip(extra, late, strict=True)]
                await _settled(extra)
                statuses = Counter(r.status for r in extra)
                say(f"one stream each for {len(late)} more participants: {dict(statuses)} (200 up to the cap of "
                    f"{cap}, 503 beyond)")
                ok = ok and statuses[503] == len(late) - 50
                stop.set()
                await asyncio.gather(*solo_tasks, *tasks, *extra_tasks, return_exceptions=True)

        asyncio.run(run())
        say(f"held: {'yes' if ok else 'NO'} (two streams per token at most, /healthz p99 under "
            f"{TARGET_STREAMS_P99_MS:.0f} ms)")
        return ok
    finally:
        server.stop()


def attack_wrong_keys(folder: Path, n: int) -> bool:
    say(f"\n== wrong keys: {n} wrong experimenter keys from one address, the right key every 10th request")
    server = Server(folder)
    try:
        wrong: Counter[int] = Counter()
        right: Counter[int] = Counter()
        with HealthProbe(server.port) as probe, httpx.Client(base_url=server.url, timeout=30) as client:
            for i in range(n):
                key = TOKEN if i % 10 == 9 else "wrong-" + secrets.token_urlsafe(32)
                status = client.get("/api/v1/studies", headers={"Authorization": f"Bearer {key}"}).status_code
                (right if key == TOKEN else wrong)[status] += 1
        say(f"wrong keys: {dict(sorted(wrong.items()))} (401 wrong, 429 limited); right key: {dict(right)}")
        say(probe.summary())
        ok = set(right) == {200} and wrong[429] > 0
        say(f"held: {'yes' if ok else 'NO'} (the right key always works, wrong keys are limited)")
        return ok
    finally:
        server.stop()


def attack_deep_formula(folder: Path) -> bool:
    say("\n== deep formulas: custom ground truths nested far beyond the limit")
    server = Server(folder)
    try:
        headers = {"Authorization": f"Bearer {TOKEN}"}
        ok = True
        for name, truth in (("1,990 negations", "!" * 1990 + "F(bowl)"),
                            ("996 parentheses", "(" * 996 + "F(bowl)" + ")" * 996),
                            ("500 chained U", " U ".join(["bowl"] * 500))):
            spec = {"tasks": [{"key": "custom", "ground_truth": truth}], "conditions": ["active"]}
            r = httpx.post(f"{server.url}/api/v1/studies", json=spec, headers=headers, timeout=30)
            field = (r.json().get("errors") or [{}])[0].get("field")
            say(f"{name}: {r.status_code} naming {field!r}: {r.json()['detail'][:110]}")
            ok = ok and r.status_code == 422 and field == "tasks.0.ground_truth"
        say(f"held: {'yes' if ok else 'NO'} (422 naming the field, never a 500)")
        return ok
    finally:
        server.stop()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scale", type=float, default=1.0, help="multiply every count by this (default 1)")
    parser.add_argument("--seconds", type=float, default=10.0, help="placements under the open streams (default 10)")
    parser.add_argument("--pause", type=float, default=PLACEMENT_PAUSE,
                        help=f"seconds between a participant's actions under the streams (default {PLACEMENT_PAUSE:g})")
    parser.add_argument("--only", choices=["slow", "joins", "streams", "keys", "formula"], action="append",
                        help="run only these attacks (repeatable)")
    parser.add_argument("--probe-port", type=int, help=argparse.SUPPRESS)  # the /healthz probe's own process
    args = parser.parse_args()
    if args.probe_port:
        run_probe(args.probe_port)
        return 0
    if not 0 < args.scale <= 2 or not 0 < args.seconds <= 60 or not 0 < args.pause <= 10:
        parser.error("--scale must be in (0, 2], --seconds in (0, 60] and --pause in (0, 10]: the attacks are bounded")
    from tableteach.web.limits import raise_open_files_limit

    soft, _hard = raise_open_files_limit()
    need = int(2600 * args.scale) + 200
    if soft < need:
        parser.error(f"this process may open only {soft} files; the attacks need about {need} (ulimit -n)")
    count = lambda n: max(10, int(n * args.scale))  # noqa: E731
    chosen = args.only or ["slow", "joins", "streams", "keys", "formula"]
    held: dict[str, bool] = {}
    with tempfile.TemporaryDirectory(prefix="tableteach-abuse-") as tmp:
        root = Path(tmp)
        for name in chosen:
            (root / name).mkdir()
            if name == "slow":
                held[name] = attack_slow_headers(root / name, count(1000))
            elif name == "joins":
                (root / name / "rate").mkdir()
                (root / name / "places").mkdir()
                held[name] = attack_join_flood(root / name, count(300))
            elif name == "streams":
                held[name] = attack_event_streams(root / name, count(1000), 2 * (count(500) // 2), args.seconds,
                                                  args.pause)
            elif name == "keys":
                held[name] = attack_wrong_keys(root / name, max(40, count(200)))
            else:
                held[name] = attack_deep_formula(root / name)
    say("\nsummary: " + ", ".join(f"{name} {'held' if ok else 'NOT held'}" for name, ok in held.items()))
    return 0 if all(held.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
