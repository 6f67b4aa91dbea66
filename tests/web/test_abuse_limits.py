"""The limits of a public endpoint: slow headers and stalled bodies are closed (by `tableteach serve` and by the
bundled nginx), joins are limited per address and by a study's places, change-event streams and 3D-view sockets
are capped per participant and per process and share one read per change, and deep formulas are a 422."""

from __future__ import annotations

import json
import shutil
import socket
import ssl
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tableteach.robot import ViewAddress
from tableteach.config import Settings

from .conftest import EXPERIMENTER_TOKEN, free_port, open_study, study_spec
from .helpers import EXP, bearer, join, make_study

WAIT = 30.0  # generous: the suite runs beside CPU hogs


def _connect(port: int, tls: bool = False) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port), timeout=WAIT)
    sock.settimeout(WAIT)
    if tls:  # the bundled nginx terminates TLS with the test's self-signed certificate
        context = ssl.create_default_context()
        context.check_hostname, context.verify_mode = False, ssl.CERT_NONE
        sock = context.wrap_socket(sock, server_hostname="127.0.0.1")
    return sock


def _read_until_closed(sock: socket.socket) -> bytes:
    """Everything the server sends until it closes (or resets) the connection; socket.timeout if it never does."""
    got = b""
    try:
        while chunk := sock.recv(4096):
            got += chunk
    except (ConnectionResetError, ssl.SSLError):
        pass  # nginx's reset_timedout_connection (over TLS an abrupt close is an SSL error)
    return got


# -- slow clients ----------------------------------------------------------------------------------------------


@pytest.fixture
def slow_client_server(server_factory: Any) -> Any:
    """`tableteach serve` with a 1 s deadline for headers and for each read of a body."""
    return server_factory(TABLETEACH_HEADER_TIMEOUT_SECONDS="1", TABLETEACH_BODY_TIMEOUT_SECONDS="1")


def test_headers_not_complete_in_time_are_closed_with_408(slow_client_server: Any) -> None:
    with _connect(slow_client_server.port) as idle, _connect(slow_client_server.port) as partial:
        partial.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: ")  # never finished
        assert _read_until_closed(partial).startswith(b"HTTP/1.1 408 ")
        assert b"408" in _read_until_closed(idle)  # a connection that sent nothing at all is closed too


def test_a_stalled_body_is_dropped_and_its_connection_closed(slow_client_server: Any) -> None:
    with _connect(slow_client_server.port) as sock:
        sock.sendall(b"POST /api/v1/studies/x/join HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                     b"Content-Length: 100\r\n\r\n{\"prolific")
        _read_until_closed(sock)  # returns only because the server closed it


def test_a_slow_but_steady_client_and_a_kept_alive_one_are_served(slow_client_server: Any) -> None:
    with _connect(slow_client_server.port) as sock:
        for piece in (b"GET /healthz HTTP/1.1\r\n", b"Host: x\r\n", b"\r\n"):
            sock.sendall(piece)
            time.sleep(0.2)
        first = sock.recv(4096)
        assert first.startswith(b"HTTP/1.1 200 ")
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")  # the same connection
        assert _read_until_closed(sock).startswith(b"HTTP/1.1 200 ")


def test_health_answers_while_many_slow_connections_are_held(server_factory: Any) -> None:
    server = server_factory(TABLETEACH_HEADER_TIMEOUT_SECONDS="60")
    held = [_connect(server.port) for _ in range(200)]
    try:
        for sock in held:
            sock.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n")
        assert httpx.get(f"{server.url}/healthz", timeout=WAIT).status_code == 200
    finally:
        for sock in held:
            sock.close()


def test_serving_raises_the_open_files_limit_to_the_hard_limit() -> None:
    script = ("import resource\n"
              "soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)\n"
              "resource.setrlimit(resource.RLIMIT_NOFILE, (min(256, hard), hard))\n"
              "from tableteach.web.limits import raise_open_files_limit\n"
              "print(raise_open_files_limit() == (hard, hard), resource.getrlimit(resource.RLIMIT_NOFILE)[0] == hard)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=WAIT)
    assert out.stdout.split() == ["True", "True"], out.stderr


NGINX = shutil.which("nginx") or "/usr/sbin/nginx"


@pytest.mark.skipif(not Path(NGINX).exists(), reason="Debian's nginx is not installed (apt-get install nginx-light)")
def test_the_bundled_nginx_closes_slow_headers_and_stalled_bodies(server_factory: Any, tmp_path: Path) -> None:
    from .test_proxy import _render

    server = server_factory()
    port = free_port()
    conf = _render([server], port, tmp_path)
    text = conf.read_text()
    for directive in ("client_header_timeout 10s;", "client_body_timeout 10s;"):
        assert directive in text
        text = text.replace(directive, directive.replace("10s", "1s"))
    conf.write_text(text)
    proxy = subprocess.Popen([NGINX, "-c", str(conf), "-p", str(tmp_path), "-g", "daemon off;"],
                             stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + WAIT
        while True:
            try:
                if httpx.get(f"https://127.0.0.1:{port}/healthz", timeout=5, verify=False).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert time.monotonic() < deadline, "nginx did not answer"
            time.sleep(0.1)
        with _connect(port, tls=True) as partial, _connect(port, tls=True) as stalled:
            partial.sendall(b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Slow: ")
            stalled.sendall(b"POST /api/v1/studies/x/join HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{")
            _read_until_closed(partial)
            _read_until_closed(stalled)
    finally:
        proxy.terminate()
        proxy.wait(timeout=10)


# -- joins -------------------------------------------------------------------------------------------------------


@pytest.fixture
def limited_app(tmp_path: Path) -> Iterator[Any]:
    """An in-process app taking at most 4 joins a minute from one address."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    from tableteach.db.migrate import upgrade_head
    from tableteach.web.app import create_app

    settings = Settings(database_url=f"sqlite:///{tmp_path / 'app.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                        data_dir=tmp_path / "data", joins_per_address=4)
    upgrade_head(settings.database_url)
    with TestClient(create_app(settings)) as client:
        yield client


def test_joins_from_one_address_are_limited_with_retry_after(limited_app: Any) -> None:
    study = make_study(limited_app)
    for _ in range(4):
        join(limited_app, study)
    r = limited_app.post(f"/api/v1/studies/{study}/join", json={})
    assert r.status_code == 429 and 1 <= int(r.headers["Retry-After"]) <= 60
    assert "too many joins from this address" in r.json()["detail"]
    page = limited_app.get(f"/study/{study}/join?PROLIFIC_PID=p1", follow_redirects=False)
    assert page.status_code == 429 and "Please wait a minute" in page.text and "{" not in page.text
    assert len(limited_app.get(f"/api/v1/studies/{study}/participants", headers=EXP).json()) == 4


def test_a_full_study_answers_409_and_a_plain_page(app_client: Any) -> None:
    study = make_study(app_client, places=2)
    first, state = join(app_client, study, prolific_pid="first", session_id="s1")
    join(app_client, study)
    r = app_client.post(f"/api/v1/studies/{study}/join", json={})
    assert r.status_code == 409 and "is full" in r.json()["detail"] and "2 participant" in r.json()["detail"]
    page = app_client.get(f"/study/{study}/join?PROLIFIC_PID=late", follow_redirects=False)
    assert page.status_code == 409 and "This study is full" in page.text
    # Someone who holds a place comes back: still let in.
    again = app_client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": "first", "session_id": "s1"})
    assert again.status_code == 200 and again.json()["token"] == first
    # One leaves (declines consent): their place frees.
    app_client.post("/api/v1/me/consent", json={"agree": False, "consent_version": state["consent"]["version"]},
                    headers=bearer(first))
    join(app_client, study)
    assert app_client.post(f"/api/v1/studies/{study}/join", json={}).status_code == 409
    # Places may be raised while the study is open.
    r = app_client.patch(f"/api/v1/studies/{study}", json={"places": 3}, headers=EXP)
    assert r.status_code == 200 and r.json()["places"] == 3
    join(app_client, study)


def test_places_must_be_a_positive_whole_number(app_client: Any) -> None:
    r = app_client.post("/api/v1/studies", json=study_spec(["active"], places=0), headers=EXP)
    assert r.status_code == 422 and any(e["field"] == "places" for e in r.json()["errors"])


def test_joins_that_never_consent_do_not_unbalance_the_conditions(app_client: Any) -> None:
    study = make_study(app_client, conditions=["active", "batch"], assignment="balanced")
    consented = {"active": 0, "batch": 0}
    for _ in range(10):
        token, state = join(app_client, study)
        app_client.post("/api/v1/me/consent", json={"agree": True, "consent_version": state["consent"]["version"]},
                        headers=bearer(token))
        people = app_client.get(f"/api/v1/studies/{study}/participants", headers=EXP).json()
        consented[next(p["condition"] for p in people if p["participant_id"] == state["participant_id"])] += 1
        for _ in range(3):  # a flood of the public link that never consents
            join(app_client, study)
        assert abs(consented["active"] - consented["batch"]) <= 1, consented


# -- experimenter key --------------------------------------------------------------------------------------------


def test_a_legacy_key_hash_lets_a_verified_key_in_while_wrong_keys_wait(tmp_path: Path) -> None:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    import base64
    import hashlib

    from tableteach.web.app import create_app

    salt = b"0123456789abcdef"
    digest = hashlib.pbkdf2_hmac("sha256", EXPERIMENTER_TOKEN.encode(), salt, 1000)
    enc = lambda b: base64.urlsafe_b64encode(b).decode().rstrip("=")  # noqa: E731
    settings = Settings(database_url=f"sqlite:///{tmp_path / 'a.db'}",
                        experimenter_token_hash=f"pbkdf2_sha256$1000${enc(salt)}${enc(digest)}")
    from tableteach.db.migrate import upgrade_head

    upgrade_head(settings.database_url)
    with TestClient(create_app(settings)) as client:
        assert client.get("/api/v1/studies", headers=EXP).status_code == 200  # verified once
        for _ in range(client.app.state.key_failures.limit):
            assert client.get("/api/v1/studies", headers=bearer("wrong-key")).status_code == 401
        assert client.get("/api/v1/studies", headers=bearer("wrong-key")).status_code == 429
        assert client.get("/api/v1/studies", headers=EXP).status_code == 200


# -- formulas ----------------------------------------------------------------------------------------------------


def test_a_deep_formula_is_a_422_naming_the_field(app_client: Any) -> None:
    for truth in ("!" * 1990 + "F(bowl)", "(" * 996 + "F(bowl)" + ")" * 996):
        spec = study_spec(["active"], tasks=[{"key": "custom", "ground_truth": truth}])
        r = app_client.post("/api/v1/studies", json=spec, headers=EXP)
        assert r.status_code == 422, r.text
        (error,) = r.json()["errors"]
        # Refused by the study definition's formula rules (template clauses) before the parser's depth limit.
        assert error["field"] == "tasks.0.ground_truth" and "Recursion" not in error["message"]
    r = app_client.get("/api/v1/formulas/describe", params={"formula": "!" * 1990 + "F(bowl)"}, headers=EXP)
    assert r.status_code == 422 and "Recursion" not in r.text


def test_a_deep_formula_on_the_command_line_is_one_line_and_exit_2() -> None:
    out = subprocess.run([sys.executable, "-m", "tableteach.cli", "teach", "--server", "http://127.0.0.1:1",
                          "--study", "s", "--ground-truth", "!" * 1990 + "F(bowl)"],
                         capture_output=True, text=True, timeout=WAIT)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "nested too deeply" in out.stderr and "Traceback" not in out.stderr


# -- change-event streams and 3D-view sockets ----------------------------------------------------------------------


class ThreadServer:
    """The app served by uvicorn in a thread of the test process (so the test can look at its feeds)."""

    def __init__(self, root: Path, deadline_seconds: float = 10.0, **settings: Any) -> None:
        import uvicorn

        from tableteach.db.migrate import upgrade_head
        from tableteach.web.app import create_app
        from tableteach.web.limits import LimitedHttpToolsProtocol

        self.settings = Settings(database_url=f"sqlite:///{root / 'study.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                                 data_dir=root / "data", port=free_port(), **settings)
        upgrade_head(self.settings.database_url)
        self.app = create_app(self.settings)
        self.server = uvicorn.Server(uvicorn.Config(self.app, host="127.0.0.1", port=self.settings.port,
                                                    log_level="warning",
                                                    http=LimitedHttpToolsProtocol.with_timeouts(deadline_seconds,
                                                                                               deadline_seconds),
                                                    timeout_graceful_shutdown=1))
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + WAIT
        while not self.server.started:
            assert time.monotonic() < deadline and self.thread.is_alive(), "the server did not start"
            time.sleep(0.05)
        self.url = f"http://127.0.0.1:{self.settings.port}"

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=15)


@pytest.fixture
def stream_server(tmp_path: Path) -> Iterator[ThreadServer]:
    """Three streams per participant, five in the process."""
    server = ThreadServer(tmp_path, streams_per_participant=3, max_event_streams=5)
    yield server
    server.stop()


class EventStream:
    """A raw event-stream connection: its status and the events read so far."""

    def __init__(self, port: int, token: str) -> None:
        self.sock = _connect(port)
        # HTTP/1.0: the body comes unchunked, as the events were written
        self.sock.sendall(f"GET /p/{token}/events HTTP/1.0\r\nHost: x\r\n\r\n".encode())
        self.buffer = b""
        head = self._until(b"\r\n\r\n")
        self.status = int(head.split(b" ")[1])
        self.headers = head.decode("latin-1").lower()

    def _until(self, marker: bytes) -> bytes:
        while marker not in self.buffer:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError(f"closed before {marker!r}; got {self.buffer[-200:]!r}")
            self.buffer += chunk
        head, _, self.buffer = self.buffer.partition(marker)
        return head

    def next_event(self) -> tuple[str, dict]:
        """The next named event (keep-alive comments skipped)."""
        while True:
            block = self._until(b"\n\n").decode()
            lines = [line for line in block.splitlines() if not line.startswith((":", "retry:"))]
            name = next((line[7:] for line in lines if line.startswith("event: ")), None)
            data = next((line[6:] for line in lines if line.startswith("data: ")), "{}")
            if name is not None:
                return name, json.loads(data)

    def close(self) -> None:
        self.sock.close()


def _wait_for(condition: Any, what: str) -> None:
    deadline = time.monotonic() + WAIT
    while not condition():
        assert time.monotonic() < deadline, f"waited {WAIT} s for {what}"
        time.sleep(0.02)


def _participant(url: str) -> tuple[str, int]:
    study = open_study(url, study_spec(["active"], n_practice=0))
    r = httpx.post(f"{url}/api/v1/studies/{study}/join", json={}, timeout=WAIT)
    token, state = r.json()["token"], r.json()["state"]
    h = bearer(token)
    httpx.post(f"{url}/api/v1/me/consent", json={"agree": True, "consent_version": state["consent"]["version"]},
               headers=h, timeout=WAIT)
    httpx.post(f"{url}/api/v1/me/instructions", headers=h, timeout=WAIT)
    return token, int(state["participant_id"])


def test_one_read_per_change_is_shared_by_all_streams_of_a_participant(stream_server: ThreadServer) -> None:
    token, pid = _participant(stream_server.url)
    feeds = stream_server.app.state.event_feeds
    streams = [EventStream(stream_server.settings.port, token) for _ in range(3)]
    try:
        assert all(s.status == 200 for s in streams)
        assert all(s.next_event()[0] == "change" for s in streams)
        feed = feeds.feed(pid)
        assert feed is not None and feed.reads == 1
        r = httpx.post(f"{stream_server.url}/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token),
                       timeout=WAIT)
        assert r.status_code == 200
        events = [s.next_event() for s in streams]
        assert all(name == "change" for name, _ in events) and len({d["n"] for _, d in events}) == 1
        # One read per change, whatever the number of streams: the placement's commit and perhaps the robot's stored
        # labels right after it (its read may still be under way); three streams reading each would be 6 or more.
        assert 2 <= feed.reads <= 3
    finally:
        for s in streams:
            s.close()
    _wait_for(lambda: feeds.feed(pid) is None and feeds.slots.count == 0, "the feed to stop with its streams")


def test_a_newer_stream_ends_the_oldest_and_the_process_cap_is_a_503(stream_server: ThreadServer) -> None:
    token, pid = _participant(stream_server.url)
    other, _ = _participant(stream_server.url)
    feeds = stream_server.app.state.event_feeds
    streams = [EventStream(stream_server.settings.port, token) for _ in range(4)]
    try:
        for s in streams:
            assert s.status == 200 and s.next_event()[0] == "change"
        assert streams[0].next_event()[0] == "superseded"  # the fourth took the first one's place
        assert feeds.slots.held(pid) == 3
        more = [EventStream(stream_server.settings.port, other) for _ in range(2)]
        streams += more
        assert more[0].status == 200 and more[1].status == 200
        full = EventStream(stream_server.settings.port, other)  # the process holds five: full
        streams.append(full)
        assert full.status == 503 and "retry-after:" in full.headers
        health = httpx.get(f"{stream_server.url}/healthz", timeout=WAIT)
        assert health.status_code == 200
    finally:
        for s in streams:
            s.close()
    _wait_for(lambda: feeds.slots.count == 0, "every slot to be given back")


def test_slots_keep_the_newest_per_participant_and_refuse_beyond_the_total() -> None:
    import asyncio

    from tableteach.web.streams import StreamSlots, run_held

    async def scenario() -> list[Any]:
        slots = StreamSlots(per_key=2, total=3)
        ended: list[str] = []

        async def view(name: str) -> None:
            try:
                await asyncio.sleep(60)
            finally:
                ended.append(name)

        first = asyncio.ensure_future(run_held(slots, "p", view("first")))
        second = asyncio.ensure_future(run_held(slots, "p", view("second")))
        await asyncio.sleep(0.01)
        third = asyncio.ensure_future(run_held(slots, "p", view("third")))
        assert await asyncio.wait_for(first, WAIT) is True  # superseded: its view was cancelled
        other = asyncio.ensure_future(run_held(slots, "q", view("other")))
        await asyncio.sleep(0.01)
        refused = await run_held(slots, "r", view("refused"))  # 3 of 3 held
        counts = (slots.held("p"), slots.held("q"), slots.count)
        for task in (second, third, other):
            task.cancel()
        await asyncio.gather(second, third, other, return_exceptions=True)
        return [ended[0], refused, counts, slots.count]

    from tests.async_run import run_scenario

    assert run_scenario(scenario) == ["first", False, (2, 1, 3), 0]


@pytest.fixture
def echo_viewer(monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """A websocket echo server in a thread standing for a participant's viser server; open_viewer names it."""
    import asyncio

    import websockets

    from tableteach.web import viewer

    ready: dict[str, Any] = {}

    async def serve() -> None:
        async def echo(ws: Any) -> None:
            async for message in ws:
                await ws.send(message)

        async with websockets.serve(echo, "127.0.0.1", 0) as server:
            ready["port"] = server.sockets[0].getsockname()[1]
            ready["stop"] = asyncio.get_running_loop().create_future()
            ready["loop"] = asyncio.get_running_loop()
            await ready["stop"]

    thread = threading.Thread(target=lambda: asyncio.run(serve()), daemon=True)
    thread.start()
    _wait_for(lambda: "stop" in ready, "the echo server")
    monkeypatch.setattr(viewer.services, "open_viewer", lambda _ctx, _token: ViewAddress(ready["port"], "/"))
    yield ready["port"]
    ready["loop"].call_soon_threadsafe(ready["stop"].set_result, None)
    thread.join(timeout=10)


def test_a_third_view_of_a_participant_closes_their_first(app_client: Any, echo_viewer: int) -> None:
    study = make_study(app_client)
    token, _ = join(app_client, study)
    slots = app_client.app.state.viewer_slots
    with app_client.websocket_connect(f"/p/{token}/viewer") as first, \
            app_client.websocket_connect(f"/p/{token}/viewer") as second:
        first.send_text("one")
        assert first.receive_text() == "one"  # proxied to the (echo) view and back
        second.send_text("two")
        assert second.receive_text() == "two"
        with app_client.websocket_connect(f"/p/{token}/viewer") as third:
            third.send_text("three")
            assert third.receive_text() == "three"
            assert first.receive()["type"] == "websocket.close"  # the oldest made room for the newest
            assert slots.held(token) == 2
            second.send_text("still")
            assert second.receive_text() == "still"
    _wait_for(lambda: slots.count == 0, "every view's slot to be given back")


def test_an_open_view_and_event_stream_outlive_the_header_deadline(tmp_path: Path, echo_viewer: int) -> None:
    import asyncio

    import websockets

    server = ThreadServer(tmp_path, deadline_seconds=1.0)
    try:
        token, _pid = _participant(server.url)

        async def talk() -> list[str]:
            async with websockets.connect(f"ws://127.0.0.1:{server.settings.port}/p/{token}/viewer") as ws:
                await ws.send("before")
                first = await asyncio.wait_for(ws.recv(), WAIT)
                await asyncio.sleep(3.0)  # three header deadlines: an upgraded connection has none
                await ws.send("after")
                return [first, await asyncio.wait_for(ws.recv(), WAIT)]

        from tests.async_run import run_scenario

        assert run_scenario(talk) == ["before", "after"]
        events = EventStream(server.settings.port, token)  # and an event stream likewise
        try:
            assert events.status == 200 and events.next_event()[0] == "change"
            time.sleep(3.0)
            httpx.post(f"{server.url}/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token),
                       timeout=WAIT).raise_for_status()
            assert events.next_event()[0] == "change"
        finally:
            events.close()
    finally:
        server.stop()
