"""Hardening (issue 13): the robot seam's imports, key checks, limits, id bounds, exports and headers."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

from tests.conftest import REPO


def _imported_modules(path: Path) -> set[str]:
    """Every module a source file imports, anywhere in it (relative imports keep their dots)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            out.add("." * node.level + (node.module or ""))
    return out


def test_the_robot_seam_does_not_import_its_mujoco_implementation() -> None:
    imported = _imported_modules(REPO / "backend" / "robot.py")
    assert not [m for m in imported if "sim" in m.split(".")], imported


def test_the_app_is_composed_with_the_robot_the_settings_name(tmp_path: Path) -> None:
    from tableteach.config import Settings
    from tableteach.robot import TraceRobot
    from tableteach.web.robots import make_robot

    robot: Any = make_robot(Settings(robot="trace", robot_seconds_per_object=0.5, data_dir=tmp_path))
    assert isinstance(robot, TraceRobot) and robot.seconds_per_object == 0.5


# -- item 2 and 9: the experimenter key -------------------------------------------------------------------


def test_a_wrong_key_costs_one_sha256_not_a_password_hash(monkeypatch) -> None:
    import hashlib

    from tableteach.config import Settings
    from tableteach.web.auth import experimenter_checker

    checker, _ = experimenter_checker(Settings(experimenter_token="test-experimenter-token-0123456789"))

    def no_stretching(*_args: Any, **_kwargs: Any) -> bytes:
        raise AssertionError("a key check must not run PBKDF2")

    monkeypatch.setattr(hashlib, "pbkdf2_hmac", no_stretching)
    assert not checker.check("wrong-key-of-a-similar-length-0123")
    assert checker.check("test-experimenter-token-0123456789")


def test_wrong_keys_from_one_address_are_limited_with_retry_after(app_client) -> None:
    from .helpers import EXP, bearer

    limit = app_client.app.state.key_failures.limit
    for _ in range(limit):
        assert app_client.get("/api/v1/studies", headers=bearer("wrong-key")).status_code == 401
    for _ in range(3):  # while limited, wrong keys wait and the right key still works (a shared NAT address)
        response = app_client.get("/api/v1/studies", headers=bearer("wrong-key"))
        assert response.status_code == 429, response.text
        assert 1 <= int(response.headers["Retry-After"]) <= 60
        assert "too many wrong experimenter tokens" in response.json()["detail"]
        assert app_client.get("/api/v1/studies", headers=EXP).status_code == 200


def test_the_limiter_counts_each_address_and_forgets_old_failures(monkeypatch) -> None:
    from tableteach.web import limits

    clock = [1000.0]
    monkeypatch.setattr(limits.time, "monotonic", lambda: clock[0])
    limiter = limits.AddressLimiter(limit=3, window=60.0)
    for _ in range(3):
        limiter.record("10.0.0.1")
    assert limiter.retry_after("10.0.0.1") == 60 and limiter.retry_after("10.0.0.2") == 0
    clock[0] += 61
    assert limiter.retry_after("10.0.0.1") == 0


def test_outside_dev_mode_the_key_must_look_generated(tmp_path: Path) -> None:
    import pytest
    from pydantic import SecretStr

    from tableteach.config import Settings
    from tableteach.web.auth import experimenter_checker, generate_key

    for weak in ("aaaaaaaaaaaa", "a" * 64, "abcabcabcabcabcabcabcabcabcabcabcabc", "short-but-varied-123"):
        with pytest.raises(ValueError, match="tableteach key"):
            experimenter_checker(Settings(experimenter_token=SecretStr(weak)))
    key = generate_key()
    checker, _ = experimenter_checker(Settings(experimenter_token=SecretStr(key)))
    assert checker.check(key) and not checker.check(key[:-1])
    assert experimenter_checker(Settings(experimenter_token=SecretStr("aaaa"), dev_mode=True))[0].check("aaaa")


def test_tableteach_key_prints_a_key_the_server_accepts() -> None:
    import json
    import subprocess
    import sys

    from tableteach.config import Settings
    from tableteach.web.auth import experimenter_checker

    out = subprocess.run([sys.executable, "-m", "tableteach.cli", "key"], capture_output=True, text=True, check=True)
    made = json.loads(out.stdout)
    checker, _ = experimenter_checker(Settings(experimenter_token=made["experimenter_token"]))
    assert checker.check(made["experimenter_token"])
    by_hash, _ = experimenter_checker(Settings(experimenter_token_hash=made["experimenter_token_hash"]))
    assert by_hash.check(made["experimenter_token"]) and not by_hash.check("x" + made["experimenter_token"])


# -- item 4: ids past 2^63 -----------------------------------------------------------------------------------


def test_ids_past_the_database_range_are_a_422_naming_the_parameter(app_client) -> None:
    from .helpers import EXP, make_study

    study = make_study(app_client)
    base = f"/api/v1/studies/{study}/participants"
    for big in (2**63, 2**64 + 1, 2**31, -1, 0):
        for path in (f"{base}/{big}/belief", f"{base}/{big}/history", f"{base}/{big}/replays/0/query/0"):
            response = app_client.get(path, headers=EXP)
            assert response.status_code == 422, (path, response.text)
            assert "participant_id" in response.json()["detail"]
    for big in (2**63, 10**6, -1):
        for path in (f"{base}/1/replays/{big}/query/0", f"{base}/1/replays/0/query/{big}"):
            response = app_client.get(path, headers=EXP)
            assert response.status_code == 422, (path, response.text)
            assert "_index" in response.json()["detail"]
    assert app_client.get(f"/api/v1/studies/{study}/participants/{2**31 - 1}/belief", headers=EXP).status_code == 404


# -- item 3: size limits -------------------------------------------------------------------------------------


def test_a_body_over_one_megabyte_is_refused_with_413(app_client) -> None:
    from .helpers import make_study

    study = make_study(app_client)
    big = b'{"prolific_pid": "' + b"x" * (1 << 20) + b'"}'
    response = app_client.post(f"/api/v1/studies/{study}/join", content=big,
                               headers={"Content-Type": "application/json"})
    assert response.status_code == 413, response.text
    assert "at most 1048576 bytes" in response.json()["detail"]

    def chunks() -> Any:  # no Content-Length: counted while it is read
        for _ in range(5):
            yield b" " * (300 << 10)

    response = app_client.post(f"/api/v1/studies/{study}/join", content=chunks(),
                               headers={"Content-Type": "application/json"})
    assert response.status_code == 413, response.text
    assert app_client.post(f"/api/v1/studies/{study}/join", json={}).status_code == 201


def _raw_request(port: int, request: bytes, *, read_timeout: float = 10.0) -> bytes:
    """Send raw bytes to the server and read until it closes the connection (or the timeout)."""
    import socket

    with socket.create_connection(("127.0.0.1", port), timeout=read_timeout) as sock:
        try:
            sock.sendall(request)
        except (BrokenPipeError, ConnectionResetError):
            pass  # the server answered and closed before reading everything: what we want
        out = b""
        try:
            while chunk := sock.recv(65536):
                out += chunk
        except (ConnectionResetError, TimeoutError):
            pass
        return out


def test_the_server_refuses_huge_bodies_unread_and_huge_headers(server_factory) -> None:
    server = server_factory()
    # Announces 100 MB but sends only the headers: the answer comes at once, nothing is waited for.
    answer = _raw_request(server.port, b"POST /api/v1/studies/demo/join HTTP/1.1\r\nHost: x\r\n"
                                       b"Content-Type: application/json\r\nContent-Length: 100000000\r\n\r\n")
    assert answer.startswith(b"HTTP/1.1 413"), answer[:200]
    answer = _raw_request(server.port, b"GET /healthz HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * (1 << 20) + b"\r\n\r\n")
    assert answer.startswith(b"HTTP/1.1 431"), answer[:200]
    assert b"request headers too large" in answer
    ok = _raw_request(server.port, b"GET /healthz HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
    assert ok.startswith(b"HTTP/1.1 200"), ok[:200]


# -- item 9: viewer CSP and websocket Origin --------------------------------------------------------------------


def test_the_viewer_page_can_be_framed_only_by_this_origin(app_client) -> None:
    from .helpers import make_study

    study = make_study(app_client)
    token = app_client.post(f"/api/v1/studies/{study}/join", json={}).json()["token"]
    viewer = app_client.get(f"/p/{token}/viewer/")
    assert viewer.status_code == 200
    policy = dict(part.strip().split(" ", 1) for part in viewer.headers["content-security-policy"].split(";"))
    assert policy["frame-ancestors"] == "'self'" and policy["object-src"] == "'none'"
    assert "http" not in policy["connect-src"].replace("https", "") and "ws://testserver" in policy["connect-src"]
    assert "*" not in viewer.headers["content-security-policy"]


def test_the_viewer_socket_refuses_a_foreign_origin(app_client) -> None:
    import pytest
    from starlette.websockets import WebSocketDisconnect

    from .helpers import make_study

    study = make_study(app_client)
    token = app_client.post(f"/api/v1/studies/{study}/join", json={}).json()["token"]
    for origin in ("https://evil.example", "null", "http://testserver.evil.example"):
        with pytest.raises(WebSocketDisconnect) as refused:
            with app_client.websocket_connect(f"/p/{token}/viewer", headers={"Origin": origin}):
                pass
        assert refused.value.code == 1008 and "own page" in refused.value.reason, origin
    # Same origin gets past the check (and is then told there is no view at the consent stage).
    with pytest.raises(WebSocketDisconnect) as later:
        with app_client.websocket_connect(f"/p/{token}/viewer", headers={"Origin": "http://testserver"}):
            pass
    assert "no 3D view" in later.value.reason


def test_same_origin_accepts_the_host_or_the_public_url() -> None:
    from tableteach.web.viewer import same_origin

    assert same_origin("http://127.0.0.1:8000", "127.0.0.1:8000")
    assert same_origin("https://study.example.org", "10.0.0.5:8000", "https://study.example.org")
    assert same_origin(None, "127.0.0.1:8000")
    assert not same_origin("http://127.0.0.1:8001", "127.0.0.1:8000")
    assert not same_origin("null", "127.0.0.1:8000")


def test_csv_cells_with_leading_space_line_feed_or_full_width_signs_are_neutralised() -> None:
    from tableteach.web.exports import cell

    for value in (" =HYPERLINK(1)", "\n=1+1", "\uff1dSUM(A1)", "\u3000+1", "\uff20A1", "\uff0b1", "\uff0d1"):
        assert cell(value) == "'" + value, repr(value)
    assert cell("F(bowl) & G(!knife)") == "F(bowl) & G(!knife)"


def test_docs_pages_that_load_a_cdn_are_off_outside_dev_mode(app_client, tmp_path: Path) -> None:
    from starlette.testclient import TestClient

    from tableteach.config import Settings
    from tableteach.web.app import create_app

    assert app_client.get("/docs").status_code == 404 and app_client.get("/redoc").status_code == 404
    assert app_client.get("/openapi.json").status_code == 200
    dev = create_app(Settings(database_url=f"sqlite:///{tmp_path / 'dev.db'}", dev_mode=True, robot="trace",
                              data_dir=tmp_path))
    with TestClient(dev) as client:
        assert client.get("/docs").status_code == 200


def test_dot_env_files_are_ignored_by_git() -> None:
    import subprocess

    for name in (".env", "deploy/.env", ".env.local"):
        ignored = subprocess.run(["git", "check-ignore", "-q", "--no-index", name], cwd=REPO)
        assert ignored.returncode == 0, f"{name} is not ignored by .gitignore"


# -- item 7: recordings keyed by the participant's uid ----------------------------------------------------------


def _app(tmp_path: Path, name: str, data_dir: Path, robot: Any = None) -> Any:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Starlette deprecates httpx inside TestClient; it still works
        from starlette.testclient import TestClient

    from tableteach.config import Settings
    from tableteach.db.migrate import upgrade_head
    from tableteach.services import Context
    from tableteach.web.app import create_app

    from .conftest import EXPERIMENTER_TOKEN

    settings = Settings(database_url=f"sqlite:///{tmp_path / name}", experimenter_token=EXPERIMENTER_TOKEN,
                        robot="trace", data_dir=data_dir)
    upgrade_head(settings.database_url)
    from tableteach.web.robots import make_recording_store

    context = Context.from_settings(settings, robot, lambda db: make_recording_store(settings, db))
    app = create_app(settings, context=context)
    client = TestClient(app)
    client.ctx = app.state.context
    return client


def test_a_second_database_on_the_same_data_dir_never_shows_anothers_recording(tmp_path: Path) -> None:
    import numpy as np

    from tableteach.robot import TraceRobot
    from tableteach.sim.recording import Recording
    from tableteach.sim.recordings import SavedRecording, list_recordings, save_recording

    from .helpers import EXP, make_study, participant_uid
    from .test_analysis import participant_id, teach

    class SavingTraceRobot(TraceRobot):
        """The trace robot, saving a tiny recording of each execution it works out (as the MuJoCo robot does)."""

        def plan_execution(self, key: str, events: Any, name: str, *, speed: float = 1.0) -> Any:
            from tableteach.sim.recordings import RecordingId

            poses = np.zeros((2, 1, 7))
            poses[:, :, 3] = 1.0
            save_recording(data_dir, SavedRecording(RecordingId.parse(name), Recording(("bowl",), np.array([0., 1.]),
                                                                                       poses), (), (frozenset(),), ()))
            return super().plan_execution(key, events, name, speed=speed)

    data_dir = tmp_path / "shared-data"
    with _app(tmp_path, "a.db", data_dir, SavingTraceRobot()) as first, _app(tmp_path, "b.db", data_dir) as second:
        study_a = make_study(first)
        token_a, _ = teach(first, study_a, [True])
        pid_a = participant_id(first, token_a)
        uid_a = participant_uid(first.ctx, pid_a)
        assert {r.participant_uid for r in list_recordings(data_dir)} == {uid_a}  # named by uid, not by number
        url = f"/api/v1/studies/{study_a}/participants/{pid_a}/replays/0/query/0"
        assert first.get(url, headers=EXP).json()["source"] == "recording"

        study_b = make_study(second)
        token_b, _ = teach(second, study_b, [True])
        pid_b = participant_id(second, token_b)
        assert pid_b == pid_a  # the same number in another database ...
        replay = second.get(f"/api/v1/studies/{study_b}/participants/{pid_b}/replays/0/query/0", headers=EXP).json()
        assert replay["source"] == "trace"  # ... never shows the first participant's motion


def test_delete_recordings_removes_one_participants_files_only(app_client, tmp_path: Path) -> None:
    import numpy as np

    from tableteach.db.tables import ParticipantRow, new_uid
    from tableteach.services import delete_recordings
    from tableteach.sim.recording import Recording
    from tableteach.sim.recordings import RecordingId, SavedRecording, list_recordings, save_recording

    data_dir = app_client.ctx.settings.data_dir
    keep, gone = new_uid(), new_uid()
    poses = np.zeros((2, 1, 7))
    poses[:, :, 3] = 1.0
    for uid in (keep, gone):
        for kind, index in (("query", 0), ("test", 1)):
            save_recording(data_dir, SavedRecording(RecordingId(uid, 0, kind, index),
                                                    Recording(("bowl",), np.array([0.0, 1.0]), poses), (), (), ()))
    assert delete_recordings(app_client.ctx, ParticipantRow(uid=gone)) == 4  # two steps, .npz and .json each
    assert {r.participant_uid for r in list_recordings(data_dir)} == {keep}
    assert delete_recordings(app_client.ctx, ParticipantRow(uid=gone)) == 0
    import pytest

    with pytest.raises(ValueError, match="32 lowercase hex digits"):
        RecordingId("../../etc", 0, "query", 0)


def test_the_migration_gives_existing_participants_distinct_uids(tmp_path: Path) -> None:
    import sqlalchemy as sa
    from alembic import command
    from alembic.config import Config

    url = f"sqlite:///{tmp_path / 'old.db'}"
    config = Config(str(REPO / "alembic.ini"))
    config.set_main_option("script_location", str(REPO / "alembic"))
    config.attributes["database_url"] = url
    command.upgrade(config, "0001")
    engine = sa.create_engine(url)
    with engine.begin() as conn:
        conn.execute(sa.text("INSERT INTO studies VALUES ('s', 'n', '[]', '[]', 'random', 0, 0, 0, 0, 'p', 'c', '[]', "
                             "'t', 'v', NULL, 'open', 0, '2026-01-01', '2026-01-01')"))
        for i in (1, 2, 3):
            conn.execute(sa.text("INSERT INTO participants (id, token, study_id, condition, seed, pilot, stage, "
                                 "task_index, created_at, last_activity_at, n_events, version) VALUES "
                                 f"({i}, 't{i}', 's', 'active', 1, 0, 'consent', 0, '2026-01-01', '2026-01-01', 0, 1)"))
    command.upgrade(config, "head")
    with engine.begin() as conn:
        uids = [row[0] for row in conn.execute(sa.text("SELECT uid FROM participants"))]
    engine.dispose()
    assert len(set(uids)) == 3 and all(len(u) == 32 and int(u, 16) >= 0 for u in uids)


# -- item 1: resuming needs the same session or browser ---------------------------------------------------------


def test_a_prolific_pid_alone_does_not_take_over_a_session(app_client) -> None:
    from .helpers import EXP, make_study

    study = make_study(app_client)
    first = app_client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": "B1", "session_id": "S1"})
    assert first.status_code == 201
    cookie = first.headers["set-cookie"].lower()
    assert "httponly" in cookie and "samesite=lax" in cookie and "path=/" in cookie
    browser = dict(app_client.cookies)
    token = first.json()["token"]

    app_client.cookies.clear()  # someone else, who knows the PID from the dashboard or an export
    for body in ({"prolific_pid": "B1"}, {"prolific_pid": "B1", "session_id": "S2"}):
        stolen = app_client.post(f"/api/v1/studies/{study}/join", json=body)
        assert stolen.status_code == 409, stolen.text
        assert token not in stolen.text and stolen.json()["state"] is None
        assert "same browser" in stolen.json()["detail"]
        app_client.cookies.clear()
    link = app_client.get(f"/study/{study}/join?PROLIFIC_PID=B1", follow_redirects=False)
    assert link.status_code == 409 and token not in link.text
    app_client.post(f"/api/v1/studies/{study}/close", headers=EXP)
    app_client.cookies.clear()
    closed = app_client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": "B1"})
    assert closed.status_code == 409 and token not in closed.text

    # The participant themself: the same Prolific session from another browser, or the same browser.
    app_client.cookies.clear()
    again = app_client.post(f"/api/v1/studies/{study}/join", json={"prolific_pid": "B1", "session_id": "S1"})
    assert again.status_code == 200 and again.json()["token"] == token
    app_client.cookies.clear()
    app_client.cookies.update(browser)
    link = app_client.get(f"/study/{study}/join?PROLIFIC_PID=B1", follow_redirects=False)
    assert link.status_code == 303 and link.headers["location"] == f"/p/{token}"


def test_a_browser_that_joined_by_link_can_come_back_without_the_session_id(app_client) -> None:
    from .helpers import make_study

    study = make_study(app_client)
    first = app_client.get(f"/study/{study}/join?PROLIFIC_PID=P7&STUDY_ID=x", follow_redirects=False)
    assert first.status_code == 303 and "tableteach_browser" in app_client.cookies
    again = app_client.get(f"/study/{study}/join?PROLIFIC_PID=P7", follow_redirects=False)
    assert again.status_code == 303 and again.headers["location"] == first.headers["location"]


# -- item 5: storage faults ---------------------------------------------------------------------------------------


def _busy_app(tmp_path: Path) -> Any:
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    from tableteach.config import Settings
    from tableteach.db.migrate import upgrade_head
    from tableteach.web.app import create_app

    from .conftest import EXPERIMENTER_TOKEN

    settings = Settings(database_url=f"sqlite:///{tmp_path / 'busy.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                        robot="trace", data_dir=tmp_path / "data", database_busy_seconds=0.3)
    upgrade_head(settings.database_url)
    client = TestClient(create_app(settings))
    client.ctx = client.app.state.context
    return client


def test_a_database_locked_by_another_process_is_a_503_with_retry_after(tmp_path: Path, caplog) -> None:
    import sqlite3

    from .helpers import bearer, make_study

    with _busy_app(tmp_path) as client:
        study = make_study(client)
        token = client.post(f"/api/v1/studies/{study}/join", json={}).json()["token"]
        other = sqlite3.connect(tmp_path / "busy.db", isolation_level=None)
        other.execute("BEGIN EXCLUSIVE")  # as a backup tool or a second server would
        try:
            answer = client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"},
                                 headers=bearer(token))
            assert answer.status_code == 503, answer.text
            assert answer.headers["Retry-After"] == "2" and "try again" in answer.json()["detail"]
            assert "database busy" in caplog.text
            # Writers of this process queue on its lock: they too get 503 after the timeout, not a hang.
            client.ctx.db._write_lock.acquire()
            try:
                queued = client.post(f"/api/v1/studies/{study}/join", json={})
                assert queued.status_code == 503, queued.text
            finally:
                client.ctx.db._write_lock.release()
        finally:
            other.execute("ROLLBACK")
            other.close()
        ok = client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=bearer(token))
        assert ok.status_code == 200 and ok.json()["stage"] == "instructions"


def test_a_deleted_database_file_fails_health_and_refuses_writes(tmp_path: Path, caplog) -> None:
    import os

    from .helpers import bearer, make_study

    with _busy_app(tmp_path) as client:
        study = make_study(client)
        token = client.post(f"/api/v1/studies/{study}/join", json={}).json()["token"]
        assert client.get("/healthz").status_code == 200
        for suffix in ("", "-wal", "-shm"):
            path = tmp_path / f"busy.db{suffix}"
            if path.exists():
                os.remove(path)
        health = client.get("/healthz")
        assert health.status_code == 503 and "Retry-After" in health.headers
        write = client.post("/api/v1/me/consent", json={"agree": True, "consent_version": "1"}, headers=bearer(token))
        assert write.status_code == 503 and "Nothing you did was lost" in write.json()["detail"]
        assert client.get("/api/v1/me", headers=bearer(token)).status_code == 503
        assert client.post(f"/api/v1/studies/{study}/join", json={}).status_code == 503
        assert not (tmp_path / "busy.db").exists()  # no empty database was created in its place
        assert "was deleted under the running server" in caplog.text


# -- item 8: hermetic tests ------------------------------------------------------------------------------------


def test_under_the_tests_the_settings_defaults_are_outside_the_checkouts_var() -> None:
    from sqlalchemy.engine import make_url

    from tableteach.config import Settings

    from ..conftest import CHECKOUT_VAR

    defaults = Settings()
    database = Path(make_url(defaults.database_url).database or "").resolve()
    for path in (Path(defaults.data_dir).resolve(), database):
        assert not path.is_relative_to(CHECKOUT_VAR.resolve()), path


def test_a_server_the_tests_start_keeps_its_files_in_its_temp_folder(server_factory, tmp_path: Path) -> None:
    from .conftest import open_study, study_spec

    server = server_factory()
    open_study(server.url, study_spec(["active"]))
    assert server.proc is not None
    raw = Path(f"/proc/{server.proc.pid}/environ").read_bytes().split(b"\0")
    environ = dict(item.decode().split("=", 1) for item in raw if b"=" in item)
    assert Path(environ["TABLETEACH_DATA_DIR"]).resolve().is_relative_to(tmp_path.resolve())


def test_the_var_guard_notices_a_changed_file(tmp_path: Path) -> None:
    from ..conftest import var_snapshot

    folder = tmp_path / "var"
    assert var_snapshot(folder) is None
    (folder / "data").mkdir(parents=True)
    (folder / "data" / "x.npz").write_bytes(b"1")
    before = var_snapshot(folder)
    assert before == var_snapshot(folder)
    (folder / "data" / "x.npz").write_bytes(b"12")
    assert var_snapshot(folder) != before
