"""The dashboard's analysis endpoints: history, curves, live table and replays hold exactly what happened; only
the experimenter may read them."""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np
import pytest

from tableteach.core.belief import Belief
from tableteach.core.domain import get_domain
from tableteach.core.hypotheses import get_space
from tableteach.services import TASK_FORMULAS

from .helpers import EXP, bearer, demonstrate, make_study, participant_uid, to_teaching

SPACE = get_domain("dinner").clause_space
ALL = ["dinner_plate", "small_plate", "bowl", "knife", "fork"]


def robot_turn(client: Any, token: str, acceptable: bool | None) -> dict[str, Any]:
    """Let the robot carry out the current query or test, then label it; the execution as the participant saw it."""
    response = client.post("/api/v1/me/execution", headers=bearer(token))
    assert response.status_code == 200, response.text
    execution = response.json()["execution"]
    assert execution["status"] == "finished"  # the trace robot without delay finishes at once
    assert client.post("/api/v1/me/assessment", json={"acceptable": acceptable},
                       headers=bearer(token)).status_code == 200
    return execution


def teach(client: Any, study_id: str, query_labels: list[bool], test_labels: list[bool | None] | None = None
          ) -> tuple[str, list[dict[str, Any]]]:
    """Practice, two demonstrations, queries labelled as given and tests (None: stop before them); what happened."""
    token, _ = to_teaching(client, study_id)
    done = []
    demonstrate(client, token, ["bowl", "fork"])
    done.append({"kind": "practice", "index": 0, "objects": ["bowl", "fork"], "acceptable": None})
    for i, objects in enumerate([ALL, ["dinner_plate", "knife", "small_plate", "fork", "bowl"]]):
        demonstrate(client, token, objects)
        done.append({"kind": "demonstration", "index": i, "objects": objects, "acceptable": True})
    for i, label in enumerate(query_labels):
        ex = robot_turn(client, token, label)
        done.append({"kind": "query", "index": i, "objects": ex["events"], "trace": ex["trace"], "acceptable": label})
    for i, label in enumerate(test_labels or []):
        ex = robot_turn(client, token, label)
        done.append({"kind": "test", "index": i, "objects": ex["events"], "trace": ex["trace"], "acceptable": label})
    return token, done


def participant_id(client: Any, token: str) -> int:
    return client.get("/api/v1/me", headers=bearer(token)).json()["participant_id"]


def test_history_holds_every_step_and_the_belief_after_each(app_client: Any) -> None:
    study_id = make_study(app_client)
    token, done = teach(app_client, study_id, [False, True, True], [None, True, False])
    pid = participant_id(app_client, token)
    response = app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/history", headers=EXP)
    assert response.status_code == 200, response.text
    data = response.json()
    assert data["participant"]["participant_id"] == pid and data["participant"]["stage"] == "questionnaire"
    [task] = data["tasks"]
    assert task["task"] == "task1" and task["ground_truth"] == TASK_FORMULAS["task1"]
    assert task["step"] == {"kind": "done", "index": 0, "total": 0}

    executions = task["executions"]
    assert [(x["kind"], x["index"], x["objects"], x["acceptable"]) for x in executions] == [
        (d["kind"], d["index"], d["objects"], d["acceptable"]) for d in done]
    assert [x["status"] for x in executions] == ["finished"] * 3 + ["assessed"] * 6
    assert [x["by"] for x in executions] == ["participant"] * 3 + ["robot"] * 6
    for x, d in zip(executions, done, strict=True):
        expected_trace = d.get("trace") or [sorted(d["objects"][:k]) for k in range(len(d["objects"]) + 1)]
        assert x["trace"] == expected_trace
    # Learning steps: demonstrations and labelled queries only, numbered in order.
    assert [x["learning_step"] for x in executions] == [None, 1, 2, 3, 4, 5, None, None, None]
    assert all(-1e-9 <= x["p_acceptable"] <= 1 + 1e-9 for x in executions if x["by"] == "robot")

    # The belief after each step, recomputed here from the traces and labels with the core alone.
    space = get_space("dinner", "chains-2020-sat")
    truth = SPACE.mask_of_formula(TASK_FORMULAS["task1"])
    belief = Belief.prior(space)
    learned = [x for x in executions if x["learning_step"]]
    assert [s["step"] for s in task["steps"]] == list(range(6))
    for k, step in enumerate(task["steps"]):
        if k:
            x = learned[k - 1]
            belief = belief.observe(tuple(frozenset(s) for s in x["trace"]), x["acceptable"])
            assert step["record"] == {"kind": x["kind"], "acceptable": x["acceptable"], "trace": x["trace"]}
        else:
            assert step["record"] is None
        assert step["entropy"] == pytest.approx(belief.entropy)
        assert step["similarity"] == pytest.approx(belief.similarity(truth))
        assert step["map_similarity"] == pytest.approx(belief.map_similarity(truth))
        top = belief.top(5)
        assert [t["formula"] for t in step["top"]] == [SPACE.text_of(m) for m, _ in top]
        assert [t["p"] for t in step["top"]] == pytest.approx([p for _, p in top])
        assert [t["description"] for t in step["top"]] == [SPACE.describe(m) for m, _ in top]
    # The belief summary endpoint agrees on the final belief.
    summary = app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/belief", headers=EXP).json()
    assert summary["tasks"][0]["entropy"] == pytest.approx(task["steps"][-1]["entropy"])

    kinds = [e["kind"] for e in data["events"]]
    assert kinds[:4] == ["joined", "consent", "instructions_read", "task_started"]
    assert [e["seq"] for e in data["events"]] == list(range(1, len(kinds) + 1))
    assert kinds.count("assessment") == 6 and kinds.count("place") == 2 + 5 + 5


def test_history_of_an_unfinished_step_and_of_the_questionnaire(app_client: Any) -> None:
    study_id = make_study(app_client, tasks=[{"key": "none"}], n_practice=0, n_demonstrations=1, n_queries=0, n_tests=0)
    token, _ = to_teaching(app_client, study_id)
    pid = participant_id(app_client, token)
    assert app_client.post("/api/v1/me/placements", json={"object": "bowl"}, headers=bearer(token)).status_code == 200
    task = app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/history", headers=EXP).json()["tasks"][0]
    assert task["ground_truth"] is None
    assert [(x["kind"], x["status"], x["objects"], x["trace"]) for x in task["executions"]] == [
        ("demonstration", "running", ["bowl"], None)]
    assert [s["similarity"] for s in task["steps"]] == [None]

    demonstrate(app_client, token, ["dinner_plate"])
    answers = {"learned": 4, "overall": 7, "comments": "=fine"}
    assert app_client.post("/api/v1/me/questionnaire", json={"answers": answers},
                           headers=bearer(token)).status_code == 200
    data = app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/history", headers=EXP).json()
    assert {a["item_id"]: a["answer"] for a in data["questionnaire"]} == answers
    assert data["participant"]["stage"] == "done" and data["participant"]["completion_code"]
    assert [(x["objects"], x["trace"]) for x in data["tasks"][0]["executions"]] == [
        (["bowl", "dinner_plate"], [[], ["bowl"], ["bowl", "dinner_plate"]])]


def test_curves_are_the_median_similarity_and_mean_entropy_per_step(app_client: Any) -> None:
    study_id = make_study(app_client, ["active", "random"], assignment="random")
    histories = []
    for labels, tests in (([False, True, True], [True, True, True]), ([True, False, True], [True, None, True]),
                          ([True], None)):
        token, _ = teach(app_client, study_id, labels, tests)
        pid = participant_id(app_client, token)
        histories.append(app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/history", headers=EXP).json())
    response = app_client.get(f"/api/v1/studies/{study_id}/curves", headers=EXP)
    assert response.status_code == 200, response.text
    [task] = response.json()["tasks"]
    assert task["has_ground_truth"] is True
    per_participant = {h["participant"]["participant_id"]: h["tasks"][0]["steps"] for h in histories}
    assert {p["participant_id"]: p["entropy"] for p in task["participants"]} == {
        pid: pytest.approx([s["entropy"] for s in steps]) for pid, steps in per_participant.items()}
    # The unfinished participant's belief reached step 3 (two demonstrations, one query): 4 points.
    assert [p["finished"] for p in task["participants"]] == [False, False, False]  # none answered the questionnaire
    assert sorted(len(p["similarity"]) for p in task["participants"]) == [4, 6, 6]
    points = task["all"]
    assert [p["n"] for p in points] == [3, 3, 3, 3, 2, 2]
    for p in points:
        sims = [steps[p["step"]]["similarity"] for steps in per_participant.values() if p["step"] < len(steps)]
        ents = [steps[p["step"]]["entropy"] for steps in per_participant.values() if p["step"] < len(steps)]
        assert p["n_similarity"] == len(sims)
        assert p["median_similarity"] == pytest.approx(statistics.median(sims))
        assert p["mean_entropy"] == pytest.approx(statistics.fmean(ents))
        assert p["q1_similarity"] == pytest.approx(float(np.quantile(sims, 0.25)))
        assert p["q3_similarity"] == pytest.approx(float(np.quantile(sims, 0.75)))
    conditions = {h["participant"]["participant_id"]: h["participant"]["condition"] for h in histories}
    for curve in task["conditions"]:
        members = [pid for pid, c in conditions.items() if c == curve["condition"]]
        assert curve["points"][0]["n"] == len(members)
    assert sorted(c["condition"] for c in task["conditions"]) == sorted(set(conditions.values()))


def test_curves_can_be_limited_to_completed_participants(app_client: Any) -> None:
    study_id = make_study(app_client, questionnaire=[], n_queries=1, n_tests=0)
    teach(app_client, study_id, [True])  # no questionnaire: done after the last query
    teach(app_client, study_id, [])  # stops before its query
    everyone = app_client.get(f"/api/v1/studies/{study_id}/curves", headers=EXP).json()["tasks"][0]
    finished = app_client.get(f"/api/v1/studies/{study_id}/curves?finished_only=true", headers=EXP).json()["tasks"][0]
    assert [p["n"] for p in everyone["all"]] == [2, 2, 2, 1]
    assert [p["n"] for p in finished["all"]] == [1, 1, 1, 1]
    assert [p["finished"] for p in finished["participants"]] == [True]


def test_live_table_shows_the_step_and_flags_inactive_unfinished_participants(app_client: Any) -> None:
    study_id = make_study(app_client, questionnaire=[], n_queries=1, n_tests=0)
    teach(app_client, study_id, [True])
    token, _ = teach(app_client, study_id, [])
    live = app_client.get(f"/api/v1/studies/{study_id}/live", headers=EXP).json()
    assert live["dropout_minutes"] == 60
    done, busy = live["participants"]
    assert (done["stage"], done["status"], done["step"], done["dropout"]) == ("done", "done", None, False)
    assert (busy["stage"], busy["status"], busy["dropout"]) == ("task", "active", False)
    assert busy["step"] == {"task_index": 0, "kind": "query", "index": 0, "total": 1}
    time.sleep(0.05)
    strict = app_client.get(f"/api/v1/studies/{study_id}/live?dropout_minutes=0.0005", headers=EXP).json()
    assert [p["dropout"] for p in strict["participants"]] == [False, True]
    assert strict["participants"][1]["inactive_minutes"] >= 0.0005
    assert app_client.get(f"/api/v1/studies/{study_id}/live?dropout_minutes=0", headers=EXP).status_code == 422


def test_replay_without_a_recording_gives_the_trace_and_the_table_layout(app_client: Any) -> None:
    study_id = make_study(app_client)
    token, done = teach(app_client, study_id, [False])
    pid = participant_id(app_client, token)
    url = f"/api/v1/studies/{study_id}/participants/{pid}/replays/0/query/0"
    data = app_client.get(url, headers=EXP).json()
    assert data["source"] == "trace" and data["recording"] is None
    assert (data["objects"], data["trace"], data["acceptable"]) == (done[3]["objects"], done[3]["trace"], False)
    layout = data["layout"]
    assert [t["name"] for t in layout["tables"]] == ["Table A", "Table B"]
    assert sorted(layout["objects"]) == sorted(ALL)
    table_b = layout["tables"][1]
    for obj in layout["objects"].values():  # every slot lies on Table B
        assert abs(obj["slot"]["x"] - table_b["x"]) < table_b["half_x"]
        assert abs(obj["slot"]["y"] - table_b["y"]) < table_b["half_y"]
    assert layout["objects"]["dinner_plate"]["shape"] == "disc" and layout["objects"]["knife"]["shape"] == "bar"
    demo = app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/replays/0/demonstration/1",
                          headers=EXP).json()
    assert demo["objects"] == done[2]["objects"] and demo["source"] == "trace"


def test_replay_of_a_saved_recording_sends_the_objects_and_the_hand_at_15_fps(app_client: Any) -> None:
    from tableteach.sim.recording import Recording
    from tableteach.sim.recordings import RecordingId, SavedRecording, save_recording

    study_id = make_study(app_client)
    token, done = teach(app_client, study_id, [True])
    pid = participant_id(app_client, token)
    times = np.arange(61) / 30  # 2 s at 30 fps
    poses = np.zeros((61, 3, 7))
    poses[:, :, 3] = 1.0
    poses[:, 0, 0] = np.linspace(0.43, 0.45, 61)  # the dinner plate travels
    poses[:, 1, 1] = np.linspace(0.3, -0.3, 61)  # the hand
    recording = Recording(("dinner_plate", "hand", "upper_arm"), times, poses)
    rid = RecordingId(participant_uid(app_client.ctx, pid), 0, "query", 0)
    saved = SavedRecording(rid, recording, tuple(done[3]["objects"]), tuple(frozenset(s) for s in done[3]["trace"]),
                           (1.0, 2.0))
    save_recording(app_client.ctx.settings.data_dir, saved)
    data = app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/replays/0/query/0", headers=EXP).json()
    assert data["source"] == "recording" and data["trace"] == done[3]["trace"]
    rec = data["recording"]
    assert rec["bodies"] == ["dinner_plate", "hand"]  # arm links other than the hand and elbow are left out
    assert rec["times"] == pytest.approx([i / 15 for i in range(31)], abs=1e-4)
    assert rec["poses"][-1][0][0] == pytest.approx(0.45) and rec["poses"][-1][1][1] == pytest.approx(-0.3)
    assert rec["action_ends"] == [1.0, 2.0]
    # Other steps of the same participant have no recording: their trace is replayed instead.
    assert app_client.get(f"/api/v1/studies/{study_id}/participants/{pid}/replays/0/demonstration/0",
                          headers=EXP).json()["source"] == "trace"


def test_replay_of_a_step_that_did_not_happen_is_404(app_client: Any) -> None:
    study_id = make_study(app_client)
    token, _ = teach(app_client, study_id, [])
    pid = participant_id(app_client, token)
    base = f"/api/v1/studies/{study_id}/participants/{pid}/replays"
    response = app_client.get(f"{base}/0/query/0", headers=EXP)
    assert response.status_code == 404 and "no query 0 in task 0" in response.json()["detail"]
    assert app_client.get(f"{base}/0/dance/0", headers=EXP).status_code == 422
    assert app_client.get(f"{base}/0/query/-1", headers=EXP).status_code == 422


def test_only_the_experimenter_can_read_the_analysis(app_client: Any) -> None:
    study_id = make_study(app_client)
    other_study = make_study(app_client)
    token, _ = teach(app_client, study_id, [True])
    pid = participant_id(app_client, token)
    urls = [f"/api/v1/studies/{study_id}/live", f"/api/v1/studies/{study_id}/curves",
            f"/api/v1/studies/{study_id}/participants/{pid}/history",
            f"/api/v1/studies/{study_id}/participants/{pid}/replays/0/demonstration/0"]
    for url in urls:
        assert app_client.get(url, headers=EXP).status_code == 200, url
        for headers in ({}, bearer(token), bearer("not-the-token-at-all")):
            response = app_client.get(url, headers=headers)
            assert response.status_code == 401, (url, headers, response.text)
            assert "experimenter" in response.json()["detail"]
    # A participant is only found under their own study.
    for url in (f"/api/v1/studies/{other_study}/participants/{pid}/history",
                f"/api/v1/studies/{other_study}/participants/{pid}/replays/0/demonstration/0"):
        response = app_client.get(url, headers=EXP)
        assert response.status_code == 404 and f"no participant {pid}" in response.json()["detail"]
    for url in ("/api/v1/studies/nope/live", "/api/v1/studies/nope/curves"):
        assert app_client.get(url, headers=EXP).status_code == 404


def test_the_dashboard_page_and_only_its_own_assets_are_served(app_client: Any) -> None:
    page = app_client.get("/dashboard")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert '<script type="module" src="/dashboard/assets/dashboard.js">' in page.text
    assert "script-src 'self'" in page.headers["content-security-policy"]
    for name, kind in (("dashboard.js", "text/javascript"), ("dashboard-api.js", "text/javascript"),
                       ("charts.js", "text/javascript"), ("dom.js", "text/javascript"), ("dashboard.css", "text/css")):
        response = app_client.get(f"/dashboard/assets/{name}")
        assert response.status_code == 200 and response.headers["content-type"].startswith(kind), name
    for name in ("dashboard.html", "api.js", "..%2Fpyproject.toml", "nope.js"):
        assert app_client.get(f"/dashboard/assets/{name}").status_code == 404, name


def test_a_new_learning_step_costs_the_dashboard_one_belief_summary_not_all_of_them() -> None:
    from tableteach.services import analysis
    from tableteach.core import session as core
    from tableteach.services.monitoring import belief_view

    config = core.SessionConfig(task="dinner", prior="chains-2020-sat", protocol="active", n_practice=0,
                                n_demonstrations=3, n_queries=1, n_tests=0, seed=5)
    state = core.start(config)
    truth = TASK_FORMULAS["task1"]
    # Orders no other test demonstrates, so that each new step is new to the cache.
    demos = [["fork", "knife", "bowl"], ["knife", "fork", "small_plate", "bowl"], ["fork", "bowl", "knife"]]
    analysis._step_summaries(state.to_json(), truth, 5)  # the prior's step
    for i, objects in enumerate(demos):
        state = core.observe(state, "demonstration", [sorted(objects[:k]) for k in range(len(objects) + 1)])
        before = belief_view.cache_info()
        steps = analysis._step_summaries(state.to_json(), truth, 5)
        after = belief_view.cache_info()
        assert len(steps) == i + 2
        assert after.misses - before.misses == 1  # only the newest step is computed
        # and what it shows is the belief after exactly those demonstrations
        expected = core.beliefs_by_step(state)[-1]
        assert steps[-1]["entropy"] == pytest.approx(expected.entropy)
        assert steps[-1]["similarity"] == pytest.approx(expected.similarity(SPACE.mask_of_formula(truth)))
