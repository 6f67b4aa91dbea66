"""The participant page's server side with the MuJoCo robot: the viser websocket proxy, the page and its
assets, the one-tab lease, click-free REST sessions that save recordings, one viser server per process whose
views are freed when they close, views rebuilt from the stored placements, and clicks queued to the runtime."""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator
from importlib.metadata import version
from pathlib import Path
from typing import Any

import pytest

from tableteach.services import TabLeases
from tableteach.sim.recordings import list_recordings, load_recording

from tests.waiting import wait_until

from .conftest import EXPERIMENTER_TOKEN
from .helpers import bearer, demonstrate, make_study, participant_uid, to_teaching


# Working out a MuJoCo execution on a loaded machine: the robot's worker process has 120 s, then a second try,
# then the server works it out itself; the test waits for all of that.
MUJOCO_WAIT_SECONDS = 420.0


@pytest.fixture
def mujoco_client(tmp_path: Path) -> Iterator[Any]:
    """An in-process app with the MuJoCo robot; .ctx is its services context."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    from tableteach.config import Settings
    from tableteach.db.migrate import upgrade_head
    from tableteach.web.app import create_app

    settings = Settings(database_url=f"sqlite:///{tmp_path / 'app.db'}", experimenter_token=EXPERIMENTER_TOKEN,
                        robot="mujoco", data_dir=tmp_path / "data")
    upgrade_head(settings.database_url)
    app = create_app(settings)
    with TestClient(app) as client:
        client.ctx = app.state.context  # type: ignore[attr-defined]
        yield client


def test_the_proxy_forwards_visers_subprotocol_and_checks_the_token(mujoco_client):
    from starlette.websockets import WebSocketDisconnect

    study_id = make_study(mujoco_client, n_practice=0)
    token, _state = to_teaching(mujoco_client, study_id)
    protocol = f"viser-v{version('viser')}"
    with mujoco_client.websocket_connect(f"/p/{token}/viewer", subprotocols=[protocol]) as ws:
        assert ws.accepted_subprotocol == protocol
        assert len(ws.receive_bytes()) > 0  # viser's scene, relayed from its own port
    with pytest.raises(WebSocketDisconnect) as refused:
        with mujoco_client.websocket_connect("/p/not-a-token/viewer", subprotocols=[protocol]):
            pass
    assert refused.value.code == 1008


def test_no_view_outside_a_task(mujoco_client):
    from starlette.websockets import WebSocketDisconnect

    study_id = make_study(mujoco_client)
    state = mujoco_client.post(f"/api/v1/studies/{study_id}/join", json={}).json()["state"]
    assert mujoco_client.post("/api/v1/me/view", headers=bearer(state["token"])).json() == {"available": False,
                                                                                             "url": None}
    with pytest.raises(WebSocketDisconnect):
        with mujoco_client.websocket_connect(f"/p/{state['token']}/viewer"):
            pass


def test_the_page_its_assets_and_the_viewer_page(mujoco_client):
    study_id = make_study(mujoco_client)
    token = mujoco_client.post(f"/api/v1/studies/{study_id}/join", json={}).json()["token"]
    page = mujoco_client.get(f"/p/{token}")
    assert page.status_code == 200 and "participant.js" in page.text
    assert page.headers["referrer-policy"] == "no-referrer"
    for name in ("api.js", "participant.js", "participant-views.js", "dom.js", "style.css", "goal-task1.png",
                 "goal-task2.png"):
        assert mujoco_client.get(f"/participant/assets/{name}").status_code == 200, name
    assert mujoco_client.get("/participant/assets/dashboard.js").status_code == 404
    assert mujoco_client.get("/participant/assets/..%2Fbackend%2Fconfig.py").status_code == 404
    viewer = mujoco_client.get(f"/p/{token}/viewer/", headers={"Accept-Encoding": "gzip"})
    assert viewer.status_code == 200 and viewer.text.lstrip().lower().startswith("<!doctype html")
    assert mujoco_client.get("/p/not-a-token/viewer/").status_code == 404


def test_one_tab_holds_the_page_until_it_lets_go_or_is_taken_over(mujoco_client):
    study_id = make_study(mujoco_client)
    h = bearer(mujoco_client.post(f"/api/v1/studies/{study_id}/join", json={}).json()["token"])

    def claim(tab: str, takeover: bool = False) -> bool:
        response = mujoco_client.post("/api/v1/me/tab", json={"tab_id": tab, "takeover": takeover}, headers=h)
        assert response.status_code == 200, response.text
        return response.json()["held"]

    assert claim("first-tab-1") and claim("first-tab-1")
    assert not claim("second-tab-2")
    assert claim("second-tab-2", takeover=True)
    assert not claim("first-tab-1")
    assert mujoco_client.post("/api/v1/me/tab/release", json={"tab_id": "first-tab-1"}, headers=h).status_code == 204
    assert not claim("first-tab-1")  # only the holder can let go
    mujoco_client.post("/api/v1/me/tab/release", json={"tab_id": "second-tab-2"}, headers=h)
    assert claim("first-tab-1")
    assert mujoco_client.post("/api/v1/me/tab", json={"tab_id": "x"}, headers=h).status_code == 422


def test_a_stale_lease_expires(monkeypatch):
    import sys
    from types import SimpleNamespace

    clock = [1000.0]  # the leases' own clock, moved by hand: no test time passes
    monkeypatch.setattr(sys.modules[TabLeases.__module__], "time", SimpleNamespace(monotonic=lambda: clock[0]))
    leases = TabLeases(seconds=30.0)
    assert leases.claim(1, "a-tab-0001") and not leases.claim(1, "b-tab-0002")
    clock[0] += 29.9
    assert not leases.claim(1, "b-tab-0002")  # still fresh
    clock[0] += 0.2
    assert leases.claim(1, "b-tab-0002")
    assert not leases.claim(1, "a-tab-0001")  # b's lease is now the fresh one


def test_a_rest_session_with_the_mujoco_robot_records_every_step(mujoco_client):
    study_id = make_study(mujoco_client, n_practice=0, n_demonstrations=1, n_queries=1, n_tests=1)
    token, state = to_teaching(mujoco_client, study_id)
    h = bearer(token)
    after = demonstrate(mujoco_client, token, ["dinner_plate", "bowl"])
    assert after["step"]["kind"] == "query"
    for kind in ("query", "test"):
        assert mujoco_client.post("/api/v1/me/execution", headers=h).status_code == 200
        me = wait_until(lambda: (m := mujoco_client.get("/api/v1/me", headers=h).json())["execution"]["status"]
                        == "finished" and m, f"the MuJoCo robot to finish the {kind}",
                        timeout=MUJOCO_WAIT_SECONDS, interval=0.1)
        assert me["execution"]["kind"] == kind
        events, trace = me["execution"]["events"], me["execution"]["trace"]
        assert len(trace) == len(events) + 1 and set(trace[-1]) == set(events)  # MuJoCo set each one in its slot
        assert mujoco_client.post("/api/v1/me/assessment", json={"acceptable": True}, headers=h).status_code == 200
    data_dir = mujoco_client.ctx.settings.data_dir
    saved = list_recordings(data_dir, participant_uid(mujoco_client.ctx, state["participant_id"]))
    assert [(r.step_kind, r.step_index) for r in saved] == [("demonstration", 0), ("query", 0), ("test", 0)]
    demo = load_recording(data_dir, saved[0])
    assert demo.events == ("dinner_plate", "bowl")
    assert demo.trace == (frozenset(), frozenset({"dinner_plate"}), frozenset({"dinner_plate", "bowl"}))
    assert len(demo.recording) > 300 and demo.action_ends[-1] == pytest.approx(demo.recording.times[-1], abs=1.5)
    # The task is over: its table and view are gone.
    assert mujoco_client.ctx.robot.scene(f"{state['participant_id']}/0") is None


def _viewer(client: Any, token: str) -> Any:
    return client.websocket_connect(f"/p/{token}/viewer", subprotocols=[f"viser-v{version('viser')}"])


def _camera(ws: Any) -> None:
    """Report a camera as viser's client does on connecting (viser counts a browser only after that)."""
    import msgpack

    ws.send_bytes(msgpack.packb({"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
                                 "position": [2.0, 0.0, 1.5], "image_height": 600, "image_width": 800,
                                 "fov": 0.9, "near": 0.01, "far": 100.0, "look_at": [0.0, 0.0, 0.4],
                                 "up_direction": [0.0, 0.0, 1.0]}))


def _until(condition: Any, what: str, within: float = 60.0) -> None:
    deadline = time.monotonic() + within
    while not condition():
        assert time.monotonic() < deadline, what
        time.sleep(0.05)


def test_every_view_of_a_process_is_a_client_of_one_viser_server_and_is_freed_when_it_closes(mujoco_client):
    study_id = make_study(mujoco_client, n_practice=0)
    robot = mujoco_client.ctx.robot
    tokens = [to_teaching(mujoco_client, study_id)[0] for _ in range(3)]
    with _viewer(mujoco_client, tokens[0]) as a, _viewer(mujoco_client, tokens[1]) as b, \
            _viewer(mujoco_client, tokens[2]) as c:
        for ws in (a, b, c):
            assert len(ws.receive_bytes()) > 0
            _camera(ws)
        _until(lambda: robot.view_count() == 3, "the three browsers never joined the one viser server")
        ports = {robot.open_view(f"{pid}/0", None).port for pid in (1, 2, 3)}
        assert len(ports) == 1  # one server, one port, for every table
    _until(lambda: robot.view_count() == 0, "closed views were not freed")


def test_a_view_opened_after_a_restart_shows_the_stored_placements(mujoco_client):
    study_id = make_study(mujoco_client, n_practice=0, n_demonstrations=2)
    token, state = to_teaching(mujoco_client, study_id)
    h = bearer(token)
    for obj in ("dinner_plate", "bowl"):
        assert mujoco_client.post("/api/v1/me/placements", json={"object": obj}, headers=h).status_code == 200
    key = f"{state['participant_id']}/0"
    mujoco_client.ctx.robot.release(key)  # as after a restart: the robot holds no table
    assert mujoco_client.ctx.robot.placed(key) is None
    with _viewer(mujoco_client, token) as ws:
        assert len(ws.receive_bytes()) > 0
        assert mujoco_client.ctx.robot.placed(key) == ("dinner_plate", "bowl")  # rebuilt before it was shown
        world = mujoco_client.ctx.robot.scene(key)
        assert world is not None and set(world.labels()) == {"dinner_plate", "bowl"}


def test_a_click_in_the_view_is_carried_out_on_the_runtime_not_on_visers_thread(mujoco_client):
    import threading

    study_id = make_study(mujoco_client, n_practice=0)
    token, state = to_teaching(mujoco_client, study_id)
    key = f"{state['participant_id']}/0"
    ctx = mujoco_client.ctx
    threads: list[str] = []
    original = ctx.runtime.submit

    def noted(action: Any) -> Any:
        def run() -> Any:
            threads.append(threading.current_thread().name)
            return action()
        return original(run)

    ctx.runtime.submit = noted  # type: ignore[method-assign]
    from tableteach import services

    services.open_viewer(ctx, token)  # arms the table's clicks, as the page's viewer does on connecting
    ctx.robot.clicked(key, "fork")  # what viser's click callback calls, on viser's thread
    _until(lambda: mujoco_client.get("/api/v1/me", headers=bearer(token)).json()["demonstration"]["placed"]
           == ["fork"], "the click was never placed")
    assert threads and threads[0].startswith("runtime-action")
    _until(lambda: ctx.robot.activity(key) is not None and not ctx.robot.activity(key).moving,
           "the table never took clicks again")
