"""Scale benchmark: N participants at once, paced as people, against K `tableteach serve` processes on PostgreSQL.

Starts a throwaway PostgreSQL cluster (Debian's server binaries, as the tests do) unless --database-url is
given, applies the migrations, starts K app processes sharing one recording store, creates a study, and
runs N simulated participants as real HTTP clients (asyncio). Participant i talks to process i % K only,
as the sticky reverse proxy (deploy/nginx.conf) would route them. Each participant:

- joins (arrivals spread over --ramp seconds), consents, reads the instructions;
- demonstrates by placing objects one at a time, pausing --think seconds (x0.5-1.5) before each action, with
  the live 3D view open (viser's websocket through the app), timing each placement's motion from the click;
- lets the robot carry out each query and test and watches it: the page asks for the view (POST /me/view),
  gets the playback URL and downloads the execution's .viser file, which the browser would play. The
  reader times the wait for the file (the robot works the execution out first; its clock starts when it
  is ready), the transfer, and reads the frame times inside the file: its frame rate and largest gap;
- follows the page's change events (GET /p/<token>/events, server-sent events) and, on each, reads GET /me and
  GET /me/robot with the ETags of its last answers (If-None-Match), as frontend/participant.js does; as a safety
  net it renews its tab lease and reads both every --poll seconds (the page's 5 s while its event stream is
  open, 1 s while it is not); then answers the questionnaire.

Targets (exit status 0 only if all hold): every REST action's p99 under 200 ms, 0 errors, every session
completed, every watched execution at 25 fps or more with no stall over 0.5 s (transfer or frame gap), and every
placement's motion in the live view at 25 fps or more with no frame gap over 0.5 s (the server sends a motion once
and the page plays it on its own clock), one motion for every placement. The waits for the robot (from the start
click to an execution's recording, from a placement's click to its motion) are printed, not judged.

It prints progress every few seconds, then p50/p99 per action, CPU seconds per app process and per
participant, the database's CPU and transactions, and last:

    participants N processes K rest_p99_ms X min_fps Y errors Z cpu_per_session_s C learner_s L

where X is the worst action's p99 (the target holds for every action, not only for all requests pooled), C the
app's CPU seconds (server and robot workers) per participant session, and L one participant's learner compute
measured in this run (benchmarks/bench_learner.py's session, on a fresh state).

    .venv/bin/python benchmarks/bench_scale.py --participants 20 --processes 2
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import secrets
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from tableteach.client import truth_mask
from tableteach.core.domain import get_domain
from tableteach.core.teachers import SimulatedTeacher

TARGET_P99_MS = 200.0
NOT_REST = "recording"  # the wait for an execution's file: timed with the actions, but it waits for the robot
TARGET_FPS = 25.0
TARGET_STALL_S = 0.5
TAB_RENEW_S = 5.0  # frontend/participant.js HEARTBEAT_MS
POLL_WITH_EVENTS_S = 5.0  # frontend/participant.js TICK_WITH_EVENTS_MS
POLL_WITHOUT_EVENTS_S = 1.0  # TICK_MS
SAFETY_NET_S = 15.0  # SAFETY_NET_MS: with change events, the state is read at least this often during a task
POSE_MESSAGES = ("SetPositionMessage", "SetOrientationMessage")
MOTION_MESSAGE = "TableTeachMotionMessage"  # backend/sim/motion_message.py
MUJOCO_SECONDS_PER_OBJECT = 5.6  # one pick-and-place of the MuJoCo arm at speed 1


# ----------------------------------------------------------------------------------------------- servers

def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cpu_seconds(pid: int, children: bool = False) -> float:
    """User + system CPU time of a process (Linux /proc); with children, also of its reaped children."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    ticks = int(fields[11]) + int(fields[12]) + ((int(fields[13]) + int(fields[14])) if children else 0)
    return ticks / os.sysconf("SC_CLK_TCK")


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(entry))
            except (OSError, ValueError, IndexError):
                continue
    return out


def _process_tree_cpu(pid: int) -> tuple[float, float]:
    """CPU seconds of a server process, and of its children (robot workers, live and ended)."""
    own = _cpu_seconds(pid)
    return own, _cpu_seconds(pid, children=True) - own + sum(_cpu_seconds(c, children=True) for c in _children(pid))


class Database:
    """The benchmark's PostgreSQL: its URL, and (when it runs on this machine) its CPU time and transactions."""

    def __init__(self, url: str) -> None:
        import psycopg

        from tableteach.db.pg_notify import libpq_url

        self.url = url
        self._conninfo = libpq_url(url)
        with psycopg.connect(self._conninfo) as conn:
            backend = conn.execute("SELECT pg_backend_pid()").fetchone()[0]
        self.postmaster: int | None = None
        try:
            with open(f"/proc/{backend}/stat") as f:
                self.postmaster = int(f.read().rsplit(")", 1)[1].split()[1])
        except OSError:
            pass  # a database on another host: no CPU figures

    def cpu_seconds(self) -> float | None:
        """The cluster's CPU time so far (postmaster, its exited children and the live ones), if local."""
        if self.postmaster is None:
            return None
        return _cpu_seconds(self.postmaster, children=True) + sum(_cpu_seconds(p) for p in _children(self.postmaster))

    def transactions(self) -> int:
        """Committed plus rolled back transactions in all databases so far."""
        import psycopg

        with psycopg.connect(self._conninfo) as conn:
            return int(conn.execute("SELECT sum(xact_commit + xact_rollback) FROM pg_stat_database").fetchone()[0])


@contextmanager
def database(url: str | None) -> Iterator[str]:
    """The given URL, or a throwaway cluster's."""
    if url is not None:
        yield url
        return
    from tableteach.db.throwaway_postgres import throwaway_postgres

    with throwaway_postgres(max_connections=300) as fresh:
        yield fresh


@contextmanager
def app_processes(k: int, url: str, folder: Path, logs: Path, token: str, robot: str,
                  speed: float, workers: int) -> Iterator[list[Any]]:
    """K `tableteach serve` processes on one database and one recording store; stopped on exit."""
    env = {**os.environ, "TABLETEACH_EXPERIMENTER_TOKEN": token, "TABLETEACH_ROBOT": robot,
           "TABLETEACH_ROBOT_SPEED": str(speed), "TABLETEACH_DATA_DIR": str(folder / "data"),
           "TABLETEACH_ROBOT_WORKERS": str(workers),
           # Every simulated participant joins from this machine's address: the per-address join limit (a guard
           # against one client joining over and over) would refuse all past the first 30 a minute.
           "TABLETEACH_JOINS_PER_ADDRESS": "100000",
           # The trace robot takes as long per object as the MuJoCo arm, so people wait as long for it.
           "TABLETEACH_ROBOT_SECONDS_PER_OBJECT": str(MUJOCO_SECONDS_PER_OBJECT / speed)}
    env.pop("TABLETEACH_DEV_MODE", None)
    procs = []
    try:
        for i in range(k):
            port = _free_port()
            log = open(logs / f"app-{i}.log", "wb")
            proc = subprocess.Popen([sys.executable, "-m", "tableteach.cli", "serve", "--port", str(port),
                                     "--database-url", url], env=env, stdout=log, stderr=subprocess.STDOUT)
            proc.url = f"http://127.0.0.1:{port}"  # type: ignore[attr-defined]
            procs.append(proc)
        for proc in procs:
            deadline = time.monotonic() + 60
            while True:
                if proc.poll() is not None:
                    raise RuntimeError(f"an app process exited with {proc.returncode}; see {logs}/app-*.log")
                try:
                    if httpx.get(f"{proc.url}/healthz", timeout=1).status_code == 200:  # type: ignore[attr-defined]
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline:
                    raise RuntimeError("an app process did not answer /healthz within 60 s")
                time.sleep(0.2)
        yield procs
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()


# ------------------------------------------------------------------------------------------ participants

@dataclass
class Results:
    """What all participants saw."""

    latencies: dict[str, list[float]] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)
    completed: int = 0
    watched: list[dict[str, float]] = field(default_factory=list)  # one per execution: fps, gap, download
    live_motions: list[dict[str, float]] = field(default_factory=list)  # one per placement shown live: fps, gap
    live_placements: int = 0  # placements made with the live view open: each should bring one motion
    not_modified: dict[str, int] = field(default_factory=dict)  # conditional reads answered 304, per action
    stale_retries: int = 0  # requests sent again after a kept-alive connection closed under them

    def rest(self, action: str, seconds: float) -> None:
        self.latencies.setdefault(action, []).append(seconds)

    def live(self, clicks: list[float], motions: list[tuple[float, dict[str, Any]]]) -> None:
        """A demonstration's live view: each placement's motion as the page receives it (once, then played on the
        page's clock): its frame rate, its largest frame gap, and the wait from the click to its arrival (printed, not
        judged, as the wait for an execution's recording is not: the robot works the placement out first)."""
        self.live_placements += len(clicks)
        for arrived, motion in motions:
            times = np.frombuffer(motion["times"], dtype="<f4").astype(float)
            span = float(times[-1] - times[0]) if len(times) > 1 else 0.0
            before = [t for t in clicks if t <= arrived]
            wait = arrived - before[-1] if before else 0.0
            gap = float(np.diff(times).max()) if len(times) > 1 else 0.0
            self.live_motions.append({"fps": (len(times) - 1) / span if span > 0 else 0.0,
                                      "max_gap": gap, "wait": wait})

    def rest_latencies(self) -> np.ndarray:
        """Every REST action's latency (the recording download, which waits for the robot, is not one)."""
        return np.array([x for name, xs in self.latencies.items() if name != NOT_REST for x in xs])


def _camera_message() -> bytes:
    """What viser's browser client sends first: its camera (msgpack, as viser.infra decodes client messages)."""
    import msgspec

    return msgspec.msgpack.encode({"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
                                   "position": [0.0, -1.5, 1.5], "fov": 1.0, "near": 0.01, "far": 100.0,
                                   "image_height": 768, "image_width": 1024, "look_at": [0.0, 0.0, 0.7],
                                   "up_direction": [0.0, 0.0, 1.0]})


CAMERA_MESSAGE = _camera_message()


def wire_motions(frame: bytes) -> list[dict[str, Any]]:
    """The placement motions in one websocket frame of viser's wire format (see viser.infra._message_producer and
    backend/sim/motion_message.py)."""
    import msgspec
    import zstandard

    size, compressed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + compressed], max_output_size=size)
    payload = msgspec.msgpack.decode(inner)
    return [m for m in payload.get("messages", ()) if m.get("type") == MOTION_MESSAGE]


def viser_frames(data: bytes) -> list[float]:
    """The distinct times (s) at which a .viser recording moves a body."""
    import msgspec
    import zstandard

    inner_size = int.from_bytes(data[:8], "little")
    inner = zstandard.ZstdDecompressor().decompress(data[8:], max_output_size=inner_size)
    n = int.from_bytes(inner[:8], "little")
    payload = msgspec.msgpack.decode(inner[8:8 + n])
    return sorted({float(t) for t, message in payload["messages"] if message.get("type") in POSE_MESSAGES})


class Participant:
    """One simulated person: the actions of the scripted teacher at a person's pace, plus what the page does by
    itself (change events, conditional reads, the lease, the safety-net poll)."""

    def __init__(self, i: int, base: str, study_id: str, results: Results, think: float, poll: float) -> None:
        self.i, self.study_id, self.results = i, study_id, results
        self.think, self.poll = think, poll
        self.http = httpx.AsyncClient(base_url=base, timeout=60)
        self.rng = np.random.default_rng(i)
        self.teacher = SimulatedTeacher(get_domain("dinner"), truth_mask("task1"), 0.1)
        self.token: str | None = None
        self.state: dict[str, Any] = {}
        self.robot: dict[str, Any] = {}
        self.tab = secrets.token_urlsafe(12)
        self.tags: dict[str, tuple[str, dict[str, Any]]] = {}  # path -> (ETag, answer), as api.js keeps them
        self.events_open = False
        self.has_view = False
        self.refreshed = asyncio.Event()  # set after every refresh: the waits below follow it, as the page does
        self._refreshing: asyncio.Task[None] | None = None
        self._again = False
        self._robot_wanted = False  # the next read also asks for the robot (a change event brings it otherwise)
        self.last_refreshed = 0.0

    async def request(self, method: str, path: str, body: Any = None, action: str | None = None,
                      revalidate: bool = False) -> dict[str, Any]:
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else {}
        if method == "POST":
            headers["Idempotency-Key"] = str(uuid.uuid4())
        held = self.tags.get(path) if revalidate else None
        if held:
            headers["If-None-Match"] = held[0]
        name = action or path.rsplit("/", 1)[-1]
        started = time.perf_counter()
        try:
            try:
                response = await self.http.request(method, path, json=body, headers=headers)
            except (httpx.ReadError, httpx.RemoteProtocolError):
                # A kept-alive connection the server closed just as this request went out: a browser sends the
                # request again on a new connection by itself (the page's actions carry an Idempotency-Key, so
                # that is safe), and so does this participant, once; counted apart from errors.
                self.results.stale_retries += 1
                response = await self.http.request(method, path, json=body, headers=headers)
        except httpx.HTTPError as exc:
            self.results.errors.append(f"{method} {name}: {exc!r}")
            raise
        self.results.rest(name, time.perf_counter() - started)
        if response.status_code == 304 and held:
            self.results.not_modified[name] = self.results.not_modified.get(name, 0) + 1
            return held[1]
        if response.status_code >= 400:
            self.results.errors.append(f"{method} {name}: HTTP {response.status_code} {response.text[:200]}")
            raise RuntimeError(f"{method} {path}: HTTP {response.status_code}")
        answer = response.json() if response.content else {}
        if revalidate and "etag" in response.headers:
            self.tags[path] = (response.headers["etag"], answer)
        return answer

    def take(self, state: dict[str, Any]) -> None:
        """A newer state (an action's answer or a read); an older read that arrives late is ignored."""
        if state.get("n_events", 0) >= self.state.get("n_events", 0):
            self.state = state

    async def pause(self) -> None:
        await asyncio.sleep(self.think * float(self.rng.uniform(0.5, 1.5)))

    async def _read_both(self) -> None:
        while True:
            self._again = False
            in_task = self.state.get("stage") == "task"
            read_robot, self._robot_wanted = in_task and self._robot_wanted, False
            me = self.request("GET", "/api/v1/me", action="GET me", revalidate=True)
            if read_robot:
                state, robot = await asyncio.gather(
                    me, self.request("GET", "/api/v1/me/robot", action="GET robot", revalidate=True))
                self.robot = robot
            else:
                state = await me
            self.take(state)
            if not in_task and state.get("stage") == "task":  # entering a task reads the robot at once
                self._again = self._robot_wanted = True
            self.refreshed.set()
            if not self._again:
                self.last_refreshed = time.monotonic()
                return

    async def refresh(self, with_robot: bool = True) -> None:
        """What the page's refresh() does: GET me and (during a task, unless a change event brought it) GET robot;
        a change meanwhile reads again."""
        self._robot_wanted = self._robot_wanted or with_robot
        if self._refreshing is not None and not self._refreshing.done():
            self._again = True
            return
        self._refreshing = asyncio.create_task(self._read_both())
        try:
            await self._refreshing
        except (httpx.HTTPError, RuntimeError):
            pass  # counted as an error already

    async def follow_events(self, stop: asyncio.Event) -> None:
        """The page's EventSource: a refresh per change event (the event's robot activity shown at once)."""
        while not stop.is_set():
            try:
                async with self.http.stream("GET", f"/p/{self.token}/events", timeout=httpx.Timeout(60, read=None),
                                            headers={"Accept": "text/event-stream"}) as response:
                    if response.status_code != 200:
                        raise RuntimeError(f"event stream: HTTP {response.status_code}")
                    self.events_open = True
                    kind = ""
                    async for line in response.aiter_lines():
                        if line.startswith("event:"):
                            kind = line[6:].strip()
                        elif line.startswith("data:") and kind == "change":
                            data = json.loads(line[5:])
                            robot = data.get("robot")
                            if robot and self.state.get("stage") == "task":
                                self.robot = robot
                                self.refreshed.set()  # the page shows the robot's news at once
                            held = self.tags.get("/api/v1/me")
                            if data.get("state") and data["state"] in (held[0] if held else None,
                                                                       self.state.get("etag")):
                                continue  # the state has not changed: the page reads nothing
                            asyncio.create_task(self.refresh(with_robot=not robot))
                        elif line.startswith("data:") and kind == "superseded":
                            self.events_open = False
                            return
            except (httpx.HTTPError, RuntimeError) as exc:
                if not stop.is_set():
                    self.results.errors.append(f"event stream: {exc!r}")
            self.events_open = False
            await asyncio.sleep(1.0)  # EventSource's retry

    async def page(self, stop: asyncio.Event) -> None:
        """The page's tick: the lease every 5 s and, during a task, a refresh (every tick without change events,
        with them every 15 s as a safety net)."""
        last_tab = 0.0
        while not stop.is_set():
            try:
                if time.monotonic() - last_tab > TAB_RENEW_S:
                    await self.request("POST", "/api/v1/me/tab", {"tab_id": self.tab}, action="tab")
                    last_tab = time.monotonic()
                due = not self.events_open or time.monotonic() - self.last_refreshed >= SAFETY_NET_S
                if self.state.get("stage") == "task" and due:
                    await self.refresh()
            except (httpx.HTTPError, RuntimeError):
                pass  # counted as an error already
            tick = self.poll if self.events_open else POLL_WITHOUT_EVENTS_S
            try:
                await asyncio.wait_for(stop.wait(), tick)
            except asyncio.TimeoutError:
                pass

    async def until(self, condition: Any) -> None:
        """Wait, as the page does, for a refresh that shows `condition` (events bring them; the tick is the net)."""
        while not condition():
            self.refreshed.clear()
            try:
                await asyncio.wait_for(self.refreshed.wait(), 60)
            except asyncio.TimeoutError:
                self.results.errors.append("no refresh for 60 s while waiting on the robot")
                raise

    async def run(self) -> None:
        joined = await self.request("POST", f"/api/v1/studies/{self.study_id}/join",
                                    {"prolific_pid": f"bench-{self.i}-{secrets.token_hex(4)}"}, action="join")
        self.token, self.state = joined["state"]["token"], joined["state"]
        stop = asyncio.Event()
        page = asyncio.create_task(self.page(stop))
        events = asyncio.create_task(self.follow_events(stop))
        try:
            await self.pause()
            self.state = await self.request("POST", "/api/v1/me/consent",
                                            {"agree": True, "consent_version": self.state["consent"]["version"]})
            await self.pause()
            self.state = await self.request("POST", "/api/v1/me/instructions")
            viewed_task = None
            while self.state["stage"] == "task":
                if viewed_task != self.state["task"]["index"]:
                    view = await self.request("POST", "/api/v1/me/view", action="view")  # the page opens the 3D view
                    self.has_view = bool(view.get("available"))
                    viewed_task = self.state["task"]["index"]
                await self.step()
            if self.state["stage"] == "questionnaire":
                await self.pause()
                answers = {item["id"]: (4 if item["kind"] == "likert5" else 8 if item["kind"] == "rating10" else "ok")
                           for item in self.state["questionnaire"]}
                self.state = await self.request("POST", "/api/v1/me/questionnaire", {"answers": answers})
            self.results.completed += self.state["stage"] == "done"
        finally:
            stop.set()
            events.cancel()
            await asyncio.gather(page, events, return_exceptions=True)
            await self.http.aclose()

    async def step(self) -> None:
        state, step = self.state, self.state["step"]
        guard = {"task_index": state["task"]["index"], "step_kind": step["kind"], "step_index": step["index"]}
        if step["kind"] in ("practice", "demonstration"):
            clicks: list[float] = []
            motions: list[tuple[float, dict[str, Any]]] = []
            # A robot without a view (trace) has no live view to read.
            reader = asyncio.create_task(self.read_live_view(motions) if self.has_view else asyncio.sleep(0))
            try:
                for obj in self.teacher.demonstrate(self.rng).events:
                    if obj in self.state["demonstration"]["placed"]:
                        continue
                    await self.pause()
                    clicks.append(time.perf_counter())
                    self.state = await self.request("POST", "/api/v1/me/placements", {"object": obj, **guard})
                    # The page keeps its buttons off until the robot has reported the table and stopped moving.
                    await self.until(lambda: self.state["demonstration"]["settled"] and not self.robot.get("moving"))
                await self.pause()
                self.state = await self.request("POST", "/api/v1/me/demonstration/finish", guard, action="finish")
            finally:
                reader.cancel()
                await asyncio.gather(reader, return_exceptions=True)
            if self.has_view:
                self.results.live(clicks, motions)
            return
        await self.pause()
        started = time.perf_counter()
        self.state = await self.request("POST", "/api/v1/me/execution", guard)
        await self.watch(started)
        await self.until(lambda: self.state["execution"]["status"] == "finished")
        await self.pause()
        trace = [frozenset(x) for x in self.state["execution"]["trace"]]
        verdict = self.teacher.assess(trace, self.rng)
        self.state = await self.request("POST", "/api/v1/me/assessment", {"acceptable": verdict, **guard},
                                        action="assessment")

    async def read_live_view(self, motions: list[tuple[float, dict[str, Any]]]) -> None:
        """The page's live 3D view during a demonstration: viser's websocket through the app; each placement's
        motion arrives once (the page then plays it), kept with its arrival time."""
        import viser
        import websockets

        base = str(self.http.base_url).rstrip("/")
        url = "ws" + base[len("http"):] + f"/p/{self.token}/viewer"
        try:
            async with websockets.connect(url, origin=base, subprotocols=[f"viser-v{viser.__version__}"],
                                          max_size=None, compression=None, open_timeout=30) as socket:
                await socket.send(CAMERA_MESSAGE)  # viser counts a client as watching once it reports its camera
                async for frame in socket:
                    if isinstance(frame, bytes):
                        arrived = time.perf_counter()
                        motions.extend((arrived, motion) for motion in wire_motions(frame))
        except (OSError, websockets.WebSocketException, asyncio.TimeoutError) as exc:
            self.results.errors.append(f"live view: {exc!r}")

    async def watch(self, started: float) -> None:
        """What the page does to show the execution: ask for the view, then download the recording it plays."""
        view = await self.request("POST", "/api/v1/me/view", action="view")
        url = view.get("url") or ""
        if "playbackPath=" not in url:
            return  # a robot without recordings (trace): nothing to watch
        from urllib.parse import parse_qs, urlparse

        path = parse_qs(urlparse(url).query)["playbackPath"][0]
        # The answer waits until the robot has worked the execution out; then the file is transferred.
        async with self.http.stream("GET", path) as response:
            ready = time.perf_counter()
            body = await response.aread()
        done = time.perf_counter()
        self.results.rest(NOT_REST, ready - started)
        if response.status_code != 200:
            self.results.errors.append(f"GET recording: HTTP {response.status_code}")
            return
        frames = viser_frames(body)
        gaps = np.diff(frames) if len(frames) > 1 else np.array([0.0])
        duration = frames[-1] - frames[0] if len(frames) > 1 else 0.0
        self.results.watched.append({"fps": (len(frames) - 1) / duration if duration > 0 else 0.0,
                                     "max_gap": float(gaps.max()), "wait": ready - started,
                                     "transfer": done - ready})


async def run_participants(n: int, urls: list[str], study_id: str, think: float, poll: float, ramp: float,
                           results: Results) -> None:
    """All participants, arriving evenly over `ramp` seconds; progress printed every 5 s."""
    participants = [Participant(i, urls[i % len(urls)], study_id, results, think, poll) for i in range(n)]

    async def arrive(p: Participant) -> None:
        await asyncio.sleep(ramp * p.i / max(1, n))
        try:
            await p.run()
        except Exception as exc:  # noqa: BLE001 - one participant's failure is counted, the others go on
            results.errors.append(f"participant {p.i} stopped: {exc!r}")

    tasks = [asyncio.create_task(arrive(p)) for p in participants]
    started = time.monotonic()
    while not all(t.done() for t in tasks):
        await asyncio.wait(tasks, timeout=5.0)
        lat = results.rest_latencies()
        p99 = float(np.percentile(lat, 99)) * 1000 if len(lat) else 0.0
        print(f"  {time.monotonic() - started:6.0f} s: {results.completed}/{n} done, {len(lat)} requests, "
              f"p99 so far {p99:.0f} ms, {len(results.watched)} executions watched, {len(results.errors)} errors",
              flush=True)


# ----------------------------------------------------------------------------------------------- main

def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--participants", type=int, default=20)
    parser.add_argument("--processes", type=int, default=1)
    parser.add_argument("--database-url", default=None,
                        help="a PostgreSQL SQLAlchemy URL (default: a throwaway cluster, as the tests use)")
    parser.add_argument("--robot", choices=("mujoco", "trace"), default="mujoco",
                        help="trace: no physics or recordings (REST load only), 5.6 s per object like the arm")
    parser.add_argument("--robot-workers", type=int, default=1,
                        help="robot worker processes per app process (TABLETEACH_ROBOT_WORKERS)")
    parser.add_argument("--robot-speed", type=float, default=1.0, help="1 = real time (an action takes ~5.6 s)")
    parser.add_argument("--warm-robot", action="store_true",
                        help="simulate the robot's placements into the data folder first, as `tableteach warm-robot "
                             "--tasks 1` does once per deployment (its CPU is printed, not counted per session)")
    parser.add_argument("--think", type=float, default=3.0, help="mean seconds a person takes before each action")
    parser.add_argument("--poll", type=float, default=POLL_WITH_EVENTS_S,
                        help="seconds between the page's safety-net refreshes while its event stream is open")
    parser.add_argument("--ramp", type=float, default=None, help="seconds over which participants arrive "
                        "(default: 0.5 s per participant, at most 60)")
    args = parser.parse_args(argv)
    if args.participants < 1 or args.processes < 1:
        parser.error("--participants and --processes must be at least 1")
    ramp = args.ramp if args.ramp is not None else min(60.0, 0.5 * args.participants)
    token = secrets.token_urlsafe(24)

    with ExitStack() as stack:
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="bench-scale-")))
        logs = Path(tempfile.mkdtemp(prefix="bench-scale-logs-"))  # kept: the app processes' logs
        print(f"database: {'given URL' if args.database_url else 'starting a throwaway PostgreSQL'}", flush=True)
        if args.warm_robot and args.robot == "mujoco":
            from tableteach.config import Settings
            from tableteach.web.robots import warm_robot

            warm_started = time.process_time()
            warm_robot(Settings(data_dir=folder / "data"), 1)
            print(f"warmed the robot's placements: {time.process_time() - warm_started:.0f} CPU s, once per data "
                  "folder (not counted below)", flush=True)
        url = stack.enter_context(database(args.database_url))
        from tableteach.db.migrate import upgrade_head

        upgrade_head(url)  # once, before the processes start (each would otherwise race to do it)
        db = Database(url)
        print(f"starting {args.processes} app process(es) ({args.robot} robot, speed {args.robot_speed}, "
              f"{args.robot_workers} robot worker(s) each)", flush=True)
        procs = stack.enter_context(app_processes(args.processes, url, folder, logs, token, args.robot,
                                                  args.robot_speed, args.robot_workers))
        urls = [p.url for p in procs]
        spec = {"name": "scale benchmark", "tasks": [{"key": "task1"}], "conditions": ["active"], "n_practice": 0,
                "n_demonstrations": 2, "n_queries": 2, "n_tests": 1,
                "questionnaire": [{"id": "overall", "text": "Overall rating", "kind": "rating10"}]}
        headers = {"Authorization": f"Bearer {token}"}
        study = httpx.post(f"{urls[0]}/api/v1/studies", json=spec, headers=headers, timeout=30).json()
        httpx.post(f"{urls[0]}/api/v1/studies/{study['id']}/open", headers=headers, timeout=30).raise_for_status()
        print(f"study: 2 demonstrations, 2 queries, 1 test; {args.participants} participants arriving over "
              f"{ramp:.0f} s, think {args.think} s, page tick {args.poll} s with change events", flush=True)

        cpu_before = [_process_tree_cpu(p.pid) for p in procs]
        db_cpu_before, xacts_before = db.cpu_seconds(), db.transactions()
        results = Results()
        started, client_cpu_before = time.monotonic(), time.process_time()
        asyncio.run(run_participants(args.participants, urls, study["id"], args.think, args.poll, ramp, results))
        wall = time.monotonic() - started
        client_cpu = time.process_time() - client_cpu_before
        cpu = [tuple(a - b for a, b in zip(_process_tree_cpu(p.pid), before, strict=True))
               for p, before in zip(procs, cpu_before, strict=True)]
        db_cpu_after, xacts = db.cpu_seconds(), db.transactions() - xacts_before

    lat = results.rest_latencies()
    p99_all = float(np.percentile(lat, 99)) * 1000 if len(lat) else float("inf")
    p99_by_action = {a: float(np.percentile(xs, 99)) * 1000 for a, xs in results.latencies.items()
                     if xs and a != NOT_REST}
    worst = max(p99_by_action, key=p99_by_action.__getitem__, default="none")
    p99 = p99_by_action.get(worst, float("inf"))  # the target is every action's p99, so the worst one counts
    print(f"\n{results.completed}/{args.participants} sessions completed in {wall:.0f} s; {len(lat)} REST requests "
          f"({len(lat) / wall:.1f}/s)")
    print(f"{'action':<14}{'n':>7}{'304s':>7}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for action, xs in sorted(results.latencies.items()):
        a = np.array(xs) * 1000
        print(f"{action:<14}{len(a):>7}{results.not_modified.get(action, 0):>7}{np.percentile(a, 50):>9.1f}"
              f"{np.percentile(a, 99):>9.1f}{a.max():>9.1f}")
    print(f"requests per session: {len(lat) / args.participants:.0f}; sent again on a new connection after the "
          f"server closed an idle kept-alive one under them (as browsers do): {results.stale_retries}")
    print(f"all requests: p99 {p99_all:.0f} ms; the worst action's p99: {worst} {p99:.0f} ms")
    for i, (server, workers) in enumerate(cpu):
        print(f"app process {i}: {server + workers:.1f} CPU s ({100 * (server + workers) / wall:.0f}% of a core): "
              f"server {server:.1f} s ({100 * server / wall:.0f}%), its robot workers {workers:.1f} s "
              f"({100 * workers / wall:.0f}%)")
    server_cpu, worker_cpu = sum(c[0] for c in cpu), sum(c[1] for c in cpu)
    print(f"app CPU per participant: {(server_cpu + worker_cpu) / args.participants:.2f} s per session "
          f"(server {server_cpu / args.participants:.2f} s, {1000 * server_cpu / max(1, len(lat)):.1f} ms per "
          f"request; robot workers {worker_cpu / args.participants:.2f} s)")
    if db_cpu_before is not None and db_cpu_after is not None:
        db_cpu = db_cpu_after - db_cpu_before
        print(f"database: {db_cpu:.1f} CPU s ({100 * db_cpu / wall:.0f}% of a core), {xacts} transactions "
              f"({xacts / wall:.0f}/s)")
    else:
        print(f"database: {xacts} transactions ({xacts / wall:.0f}/s); CPU not measured (not on this machine)")
    print(f"the simulated participants (this process): {client_cpu:.1f} CPU s ({100 * client_cpu / wall:.0f}% of a "
          f"core); machine load average {os.getloadavg()[0]:.1f} at the end")
    min_fps = min((w["fps"] for w in results.watched + results.live_motions), default=0.0)
    if results.live_motions:
        live_fps = np.array([m["fps"] for m in results.live_motions])
        waits = np.array([m["wait"] for m in results.live_motions])
        print(f"live views (demonstrations): {len(live_fps)} placement motions received for "
              f"{results.live_placements} placements (each sent once, played by the page), fps min "
              f"{live_fps.min():.1f} median {np.median(live_fps):.1f}; from the click to the "
              f"motion's arrival p50 {1000 * np.percentile(waits, 50):.0f} ms "
              f"p99 {1000 * np.percentile(waits, 99):.0f} ms max {1000 * waits.max():.0f} ms")
    if results.watched:
        waits = np.array([w["wait"] for w in results.watched])
        transfers = np.array([w["transfer"] for w in results.watched])
        recording_fps = min(w["fps"] for w in results.watched)
        print(f"watched {len(results.watched)} executions: recording fps min {recording_fps:.1f}, largest frame gap "
              f"{1000 * max(w['max_gap'] for w in results.watched):.0f} ms, transfer p50 "
              f"{1000 * np.percentile(transfers, 50):.0f} ms max {1000 * transfers.max():.0f} ms; from the start "
              f"click to the recording ready (the motion's clock starts then): p50 "
              f"{1000 * np.percentile(waits, 50):.0f} ms, max {1000 * waits.max():.0f} ms")
    for error in results.errors[:10]:
        print("error:", error)
    print(f"app process logs: {logs}")
    stall = max([max(w["max_gap"], w["transfer"]) for w in results.watched]
                + [m["max_gap"] for m in results.live_motions], default=0.0)
    every_motion = len(results.live_motions) == results.live_placements  # none shown late with the next, or never
    fps_ok = args.robot == "trace" or (bool(results.watched) and bool(results.live_motions) and every_motion
                                       and min_fps >= TARGET_FPS and stall <= TARGET_STALL_S)
    ok = (p99 < TARGET_P99_MS and not results.errors and results.completed == args.participants and fps_ok)
    print(f"targets: every action's p99 < {TARGET_P99_MS:.0f} ms, fps >= {TARGET_FPS:.0f}, "
          f"stall <= {TARGET_STALL_S} s, a motion for every placement, "
          f"0 errors, all sessions done: {'met' if ok else 'MISSED'}")
    from bench_learner import learner_seconds_per_participant  # benchmarks/ is the script's folder

    learner = learner_seconds_per_participant()
    per_session = (server_cpu + worker_cpu) / args.participants
    print(f"the learner's own compute for one participant: {1000 * learner:.0f} ms; serving a session costs "
          f"{per_session / learner:.0f} times that")
    print(f"participants {args.participants} processes {args.processes} rest_p99_ms {p99:.0f} min_fps {min_fps:.1f} "
          f"errors {len(results.errors)} cpu_per_session_s {per_session:.2f} learner_s {learner:.3f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
