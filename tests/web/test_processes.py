"""Several app processes on one PostgreSQL: a participant's requests may go to any of them, and killing the
process that started a robot execution loses nothing (the execution's clock is in the database)."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import httpx
import pytest

from tableteach.client import ParticipantClient, run_teacher
from tableteach.core.domain import get_domain

from tests.waiting import WAIT_SECONDS, wait_until

from .conftest import ServerProcess, open_study, study_spec
from .test_e2e import _check_exports_match, _exports
from .test_postgres import postgres_url  # noqa: F401 - the module's throwaway PostgreSQL cluster

pytestmark = pytest.mark.slow
SECONDS_PER_OBJECT = 1.0  # long enough that the motion is still under way when the test looks at it
MUJOCO_WAIT_SECONDS = 420.0  # the MuJoCo robot's worker has 120 s, a second try, then the server works it out


class RoundRobin(httpx.BaseTransport):
    """Sends each request to the next of several app processes (as a load balancer without stickiness would)."""

    def __init__(self, ports: list[int]) -> None:
        self.ports = ports
        self.sent: dict[int, int] = {}
        self._next = 0
        self._inner = httpx.HTTPTransport()

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        port = self.ports[self._next % len(self.ports)]
        self._next += 1
        self.sent[port] = self.sent.get(port, 0) + 1
        request.url = request.url.copy_with(port=port)
        return self._inner.handle_request(request)


def _round_robin_client(servers: list[ServerProcess], token: str | None = None) -> tuple[ParticipantClient, RoundRobin]:
    api = ParticipantClient(servers[0].url, token=token)
    transport = RoundRobin([s.port for s in servers])
    api.http.close()
    api.http = httpx.Client(base_url=servers[0].url, transport=transport, timeout=30)
    return api, transport


def _server(postgres: str, tmp_path: Path, name: str, seconds_per_object: float = SECONDS_PER_OBJECT) -> ServerProcess:
    return ServerProcess(tmp_path / f"{name}.db", database_url=postgres, TABLETEACH_DATA_DIR=str(tmp_path / "data"),
                         TABLETEACH_ROBOT_SECONDS_PER_OBJECT=str(seconds_per_object)).start()


def _placing(events: list[str]) -> list[str]:
    """The robot's caption during each action of an execution."""
    return [f"The robot is placing the {obj.replace('_', ' ')} ({i + 1} of {len(events)})"
            for i, obj in enumerate(events)]


def test_a_session_moves_between_processes_and_survives_killing_the_one_running_the_robot(
    postgres_url: str, tmp_path: Path  # noqa: F811 - the fixture imported above
) -> None:
    a, b = _server(postgres_url, tmp_path, "a"), _server(postgres_url, tmp_path, "b")
    c: ServerProcess | None = None
    try:
        study_id = open_study(a.url, study_spec(["active"]))
        # consent, instructions, practice, two demonstrations: every request alternates between a and b.
        api, transport = _round_robin_client([a, b])
        partial = run_teacher(a.url, study_id, ["task1"], seed=7, client=api, stop_after=5)
        assert transport.sent[a.port] > 3 and transport.sent[b.port] > 3

        on_a = ParticipantClient(a.url, token=partial.token)
        on_b = ParticipantClient(b.url, token=partial.token)
        asked_at = time.monotonic()  # the execution's stored clock starts between these two
        started = on_a.execute()
        answered_at = time.monotonic()
        assert started["execution"]["status"] == "running"
        events = started["execution"]["events"]
        assert len(events) >= 4
        time.sleep(max(0.0, answered_at + 2.3 * SECONDS_PER_OBJECT - time.monotonic()))
        a.kill()  # the process that started the execution dies mid-motion, b has not heard of it yet

        assert on_b.state()["execution"]["events"] == events
        # b reports the motion where its stored clock has got to (the third object or later), then follows it
        # to the end: never from the start again. The position is len(events) once b says it has stopped.
        placing, positions = _placing(events), []

        def position_on_b() -> bool:
            robot = on_b.http.get("/api/v1/me/robot", headers={"Authorization": f"Bearer {partial.token}"}).json()
            if not robot["moving"]:
                at = len(events)
            else:
                at = placing.index(robot["caption"]) if robot["caption"] in placing else -1
            positions.append(at)
            return at == len(events)

        wait_until(position_on_b, "b to follow the execution to its end")
        assert positions[0] >= 2 and positions == sorted(positions), (positions, placing)
        state = wait_until(lambda: (s := on_b.state())["execution"]["status"] == "finished" and s,
                           "b to store the execution as finished")
        # Not finished before its stored clock ran out either.
        assert time.monotonic() - asked_at >= SECONDS_PER_OBJECT * len(events) - 0.1
        assert state["execution"]["events"] == events
        assert state["execution"]["trace"] == [sorted(x) for x in get_domain("dinner").trace_of(tuple(events))]

        # A new process joins; the rest of the session alternates between it and b.
        c = _server(postgres_url, tmp_path, "c")
        api, transport = _round_robin_client([b, c], token=partial.token)
        finished = run_teacher(b.url, study_id, ["task1"], seed=7, client=api)
        assert finished.completion_code and transport.sent[c.port] > 3

        exports = _exports(c.url, study_id)
        mine = [e for e in exports["events"] if e["participant_id"] == str(partial.participant_id)]
        assert [int(e["seq"]) for e in mine] == list(range(1, len(mine) + 1))
        starts = [(e["task_index"], e["step_kind"], e["step_index"]) for e in mine if e["kind"] == "execution_started"]
        ends = [(e["task_index"], e["step_kind"], e["step_index"]) for e in mine if e["kind"] == "execution_finished"]
        assert starts == ends and len(set(starts)) == len(starts)  # each execution started and finished once
        finished.actions = partial.actions + finished.actions
        _check_exports_match(finished, exports, "active")
    finally:
        for server in (a, b, c):
            if server is not None:
                server.stop()


def test_with_the_mujoco_robot_another_process_finishes_the_execution_and_serves_its_recording(
    postgres_url: str, tmp_path: Path  # noqa: F811 - the fixture imported above
) -> None:
    robot = {"TABLETEACH_ROBOT": "mujoco", "TABLETEACH_ROBOT_SPEED": "4"}
    shared = {"database_url": postgres_url, "TABLETEACH_DATA_DIR": str(tmp_path / "data"), **robot}
    a = ServerProcess(tmp_path / "a.db", **shared).start()
    b = ServerProcess(tmp_path / "b.db", **shared).start()
    try:
        study_id = open_study(a.url, study_spec(["active"], n_practice=0, n_demonstrations=1, n_queries=1,
                                                n_tests=0))
        partial = run_teacher(a.url, study_id, ["task1"], seed=3, stop_after=3)  # consent, instructions, demo
        headers = {"Authorization": f"Bearer {partial.token}"}
        started = httpx.post(f"{a.url}/api/v1/me/execution", headers=headers, timeout=60).json()
        assert started["execution"]["status"] == "running"
        wait_until(lambda: httpx.get(f"{b.url}/api/v1/me/robot", headers=headers, timeout=60).json()[
            "caption"].startswith("The robot is placing"), "a to work the execution out", timeout=MUJOCO_WAIT_SECONDS,
            interval=0.1)
        a.kill()  # mid-motion: a worked the execution out and started it

        view = httpx.post(f"{b.url}/api/v1/me/view", headers=headers).json()
        assert "playbackPath=" in view["url"]
        recording = httpx.get(f"{b.url}/p/{partial.token}/motion/task-0/query-0.viser", timeout=60)
        assert recording.status_code == 200 and len(recording.content) > 10_000
        state = wait_until(lambda: (s := httpx.get(f"{b.url}/api/v1/me", headers=headers, timeout=60).json())[
            "execution"]["status"] == "finished" and s, "b to finish the execution after a died",
            timeout=MUJOCO_WAIT_SECONDS, interval=0.1)
        assert state["execution"]["events"] == started["execution"]["events"]
        api = ParticipantClient(b.url, token=partial.token)
        assert run_teacher(b.url, study_id, ["task1"], seed=3, client=api).completion_code
    finally:
        a.stop()
        b.stop()


def _read_events(url: str, into: list[dict], stop: threading.Event) -> None:
    """Collect a page's change events (their data) until told to stop."""
    try:
        with httpx.stream("GET", url, timeout=httpx.Timeout(WAIT_SECONDS, read=WAIT_SECONDS)) as response:
            for line in response.iter_lines():
                if line.startswith("data: "):
                    into.append(json.loads(line[len("data: "):]))
                if stop.is_set():
                    return
    except httpx.HTTPError:
        if not stop.is_set():  # the server went away while the test still listened
            raise


def test_a_page_on_one_process_follows_an_execution_started_on_another(
    postgres_url: str, tmp_path: Path  # noqa: F811 - the fixture imported above
) -> None:
    # Two seconds per object: b's page must hear of the start while the first object is still being placed.
    a, b = (_server(postgres_url, tmp_path, name, seconds_per_object=2.0) for name in "ab")
    stop = threading.Event()
    try:
        study_id = open_study(a.url, study_spec(["active"]))
        partial = run_teacher(a.url, study_id, ["task1"], seed=7, stop_after=5)
        got: list[dict] = []
        reader = threading.Thread(target=_read_events, args=(f"{b.url}/p/{partial.token}/events", got, stop),
                                  daemon=True)
        reader.start()
        wait_until(lambda: got, "the page's event stream on b to answer")  # its first event: it is listening
        started = ParticipantClient(a.url, token=partial.token).execute()
        events = started["execution"]["events"]
        captions = _placing(events)
        wait_until(lambda: len(got) >= 2 + len(events) and (got[-1]["robot"] or {}).get("moving") is False,
                   "b's page to follow the execution to its end")
        seen = [data["robot"]["caption"] for data in got[1:]]
        # The start reached b through PostgreSQL while the first object was being placed (b's stream had no
        # stored action end to wake for before the first object's end). How soon: benchmarks/bench_notify.py.
        assert seen[0] == captions[0], seen
        assert [c for c in seen if c] == captions[: len([c for c in seen if c])]
        assert set(captions) <= set(seen)  # each action in turn, then the finish
        assert got[-1]["robot"]["moving"] is False
    finally:
        stop.set()
        a.stop()
        b.stop()
