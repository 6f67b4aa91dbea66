"""Studies with 6 to 10 objects of their own through the REST API: the exact factorised learner answers every
question the server asks (through core.learner_seam), a participant teaches a seven-object study to completion, and
its exports, codebook, replay, what-if and teacher consistency hold the exact learner's numbers."""

from __future__ import annotations

import csv
import io
import json
import math
import re
import zipfile
from collections.abc import Iterator
from typing import Any

import pytest

from tableteach.core.domain import get_domain, objects_task
from tableteach.core.exact.learner import posterior_after
from tableteach.core.exact.mapping import map_formula
from tableteach.core.exact.similarity import expected_similarity

from ..study_objects import LUNCH_TRUTH, SEVEN_OBJECTS, TEN_OBJECTS, lunch_study
from .helpers import EXP, bearer, open_spec, to_teaching

NAMES = [o["name"] for o in SEVEN_OBJECTS]
TASK = objects_task(tuple(NAMES))
PRIOR = "chains-2020-sat"
DEMONSTRATIONS = (["lunch_box", "spoon", "napkin"], ["spoon", "lunch_box", "napkin", "bowl"])


def seven_study(**extra: Any) -> dict[str, Any]:
    """A lunch-packing study of seven objects: two demonstrations, two active queries, one test."""
    return lunch_study(**{"objects": SEVEN_OBJECTS, "n_demonstrations": 2, "n_queries": 2, "n_tests": 1, **extra})


def _satisfies(trace: list[list[str]]) -> bool:
    """LUNCH_TRUTH on a trace: box, napkin and spoon placed, the box before the napkin, never the mug."""
    first: dict[str, int] = {}
    for t, state in enumerate(trace):
        for obj in state:
            first.setdefault(obj, t)
    return ({"lunch_box", "napkin", "spoon"} <= set(first) and "mug" not in first
            and first["lunch_box"] <= first["napkin"])


def _until_finished(client: Any, h: dict[str, str]) -> dict[str, Any]:
    from ..waiting import wait_until

    latest: dict[str, Any] = {}

    def finished() -> bool:
        latest["state"] = client.get("/api/v1/me", headers=h).json()
        return latest["state"]["execution"]["status"] == "finished"

    wait_until(finished, timeout=300, what="the robot's execution to finish")
    return latest["state"]


def teach(client: Any, study_id: str) -> dict[str, Any]:
    """A participant's whole session by the truth: two demonstrations, a verdict on each robot execution, the
    questionnaire; the last state."""
    token, state = to_teaching(client, study_id)
    h = bearer(token)
    assert state["objects"] == NAMES
    for demonstration in DEMONSTRATIONS:
        for obj in demonstration:
            assert client.post("/api/v1/me/placements", json={"object": obj}, headers=h).status_code == 200
        state = client.post("/api/v1/me/demonstration/finish", headers=h).json()
    while state["stage"] == "task":
        assert state["step"]["kind"] in ("query", "test"), state["step"]
        assert client.post("/api/v1/me/execution", headers=h).status_code == 200
        state = _until_finished(client, h)
        assert set(state["execution"]["events"]) <= set(NAMES)
        verdict = _satisfies(state["execution"]["trace"])
        response = client.post("/api/v1/me/assessment", json={"acceptable": verdict}, headers=h)
        assert response.status_code == 200, response.text
        state = response.json()
    done = client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4}}, headers=h)
    assert done.status_code == 200 and done.json()["stage"] == "done"
    return done.json()


def _exports(client: Any, study_id: str) -> zipfile.ZipFile:
    exported = client.get(f"/api/v1/studies/{study_id}/exports/exports.zip", headers=EXP)
    assert exported.status_code == 200
    return zipfile.ZipFile(io.BytesIO(exported.content))


def _rows(files: zipfile.ZipFile, name: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(files.read(name).decode())))


def test_a_participant_teaches_a_seven_object_study_and_every_view_holds_the_exact_learners_numbers(
        app_client: Any, tmp_path: Any, capsys: Any) -> None:
    study_id = open_spec(app_client, seven_study())
    done = teach(app_client, study_id)
    domain = get_domain(TASK)
    space = domain.clause_space
    learned = done["completion"]["learned"][0]
    assert space.text_of(space.mask_of_formula(learned["map_formula"])) == learned["map_formula"]

    files = _exports(app_client, study_id)
    beliefs = _rows(files, "beliefs.csv")
    assert [int(b["step"]) for b in beliefs] == [0, 1, 2, 3, 4]  # the prior, two demonstrations, two queries
    # Every number recomputed from the exported data with core.exact directly (not through the server's seam).
    data: list[tuple[list[list[str]], bool]] = []
    truth = space.clauses_of(space.mask_of_formula(LUNCH_TRUTH))
    for row in beliefs:
        if row["record_kind"]:
            trace = json.loads(row["trace"])
            if row["record_kind"] == "query":
                before = posterior_after(domain, PRIOR, data)
                p = before.p_acceptable(before.prior.vocabulary.of_trace(trace))
                expected = p if row["acceptable"] in ("True", "true") else 1.0 - p
                assert math.isclose(float(row["p_verdict"]), expected, abs_tol=1e-9)
            else:
                assert row["p_verdict"] == ""
            data.append((trace, row["acceptable"] in ("True", "true")))
        post = posterior_after(domain, PRIOR, data)
        assert math.isclose(float(row["entropy"]), post.entropy(), abs_tol=1e-9)
        assert math.isclose(float(row["similarity"]), expected_similarity(post, truth), abs_tol=1e-9)
        best = map_formula(post)
        # The MAP and its exact probability: top1 is the MAP; the exact learner lists no other formula.
        assert row["top1_formula"] == row["map_formula"]
        assert math.isclose(float(row["top1_p"]), math.exp(best.log_probability), abs_tol=1e-9)
        assert all(row[f"top{i}_formula"] == "" and row[f"top{i}_p"] == "" for i in range(2, 6))
        assert float(row["top1_p"]) >= 0
    assert learned["map_formula"] == beliefs[-1]["map_formula"]
    assert float(beliefs[-1]["similarity"]) > float(beliefs[0]["similarity"])

    # The robot's P(acceptable) of each query, as events.csv recorded it, is the exact learner's.
    events = _rows(files, "events.csv")
    started = [e for e in events if e["kind"] == "execution_started" and e["step_kind"] == "query"]
    assert len(started) == 2
    for k, e in enumerate(started):
        before = posterior_after(domain, PRIOR, data[: 2 + k])
        events_k = json.loads(e["robot_events"])
        p = before.p_acceptable(before.prior.vocabulary.of_events(events_k))
        assert math.isclose(float(e["p_acceptable"]), p, abs_tol=1e-9)

    codebook = {(r["file"], r["column"]): r["meaning"] for r in _rows(files, "codebook.csv")}
    assert "past 5 objects: the most probable formula (map_formula)" in codebook[("beliefs.csv", "top1_formula")]
    assert "exact posterior probability" in codebook[("beliefs.csv", "top1_p")]
    assert codebook[("beliefs.csv", "top2_formula")].startswith("empty past 5 objects")
    assert "exact factorised learner" in codebook[("beliefs.csv", "entropy")]

    # The dashboard: the belief (MAP, its probability, the clause marginals), consistency, curves and what-if.
    belief = app_client.get(f"/api/v1/studies/{study_id}/participants/1/belief", headers=EXP).json()["tasks"][0]
    assert belief["learner"] == "exact" and belief["map_formula"] == beliefs[-1]["map_formula"]
    assert [t["formula"] for t in belief["top"]] == [belief["map_formula"]]
    assert belief["top"][0]["p"] == belief["map_p"]
    marginals = belief["marginals"]
    final = posterior_after(domain, PRIOR, data).marginals()
    assert len(marginals) == 10 and [m["p"] for m in marginals] == sorted((m["p"] for m in marginals), reverse=True)
    by_text = {f"F({b})" if k == "F" else f"G(!{b})" if k == "G" else f"(!{c} U {b})": p
               for (k, b, c), p in final.items()}
    assert all(math.isclose(m["p"], by_text[m["clause"]], abs_tol=1e-9) for m in marginals)
    assert marginals[0]["p"] == max(by_text.values())

    history = app_client.get(f"/api/v1/studies/{study_id}/participants/1/history", headers=EXP).json()
    steps = history["tasks"][0]["steps"]
    assert [s["learner"] for s in steps] == ["exact"] * 5
    assert [s["map_formula"] for s in steps] == [b["map_formula"] for b in beliefs]
    consistency = history["tasks"][0]["consistency"]
    exported_p = [None if b["p_verdict"] == "" else float(b["p_verdict"]) for b in beliefs]
    assert consistency["p_verdicts"] == exported_p and consistency["n_verdicts"] == 3  # two queries and the test
    live = app_client.get(f"/api/v1/studies/{study_id}/live", headers=EXP).json()["participants"][0]
    assert live["consistency"]["tasks"][0]["score"] == consistency["score"]
    curves = app_client.get(f"/api/v1/studies/{study_id}/curves", headers=EXP).json()["tasks"][0]
    mine = curves["participants"][0]
    assert mine["entropy"] == [float(b["entropy"]) for b in beliefs]
    assert mine["similarity"] == [float(b["similarity"]) for b in beliefs]

    what_if = app_client.get(f"/api/v1/studies/{study_id}/participants/1/what-if", headers=EXP)
    assert what_if.status_code == 200, what_if.text
    learners = {item["learner"]: item for item in what_if.json()["tasks"][0]["learners"]}
    assert learners["study"]["unavailable"] is None
    assert [s["similarity"] for s in learners["study"]["steps"]] == [float(b["similarity"]) for b in beliefs]
    assert learners["flip=0.1"]["steps"] == []
    assert "noise-aware learner (flip rate 0.1) is not available past 5 objects" in learners["flip=0.1"]["unavailable"]
    demos_only = learners["data=demonstrations"]["steps"]
    assert demos_only[4]["similarity"] == demos_only[2]["similarity"] == float(beliefs[2]["similarity"])

    # tableteach replay of the export reproduces the study's beliefs.
    from tableteach.cli import main

    archive = tmp_path / "exports.zip"
    archive.write_bytes(app_client.get(f"/api/v1/studies/{study_id}/exports/exports.zip", headers=EXP).content)
    code = main(["replay", str(archive), "--learner", "study", "--out", str(tmp_path / "replay"), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    with open(tmp_path / "replay" / "replay.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 5 and all(r["map_formula"] == r["study_map_formula"] for r in rows)
    assert all(abs(float(r["similarity"]) - float(r["study_similarity"])) < 1e-9 for r in rows)
    assert all(abs(float(r["entropy"]) - float(r["study_entropy"])) < 1e-9 for r in rows)
    capsys.readouterr()
    refused = main(["replay", str(archive), "--learner", "flip=0.1", "--out", str(tmp_path / "flip"), "--no-progress"])
    assert refused == 2 and "noise-aware learner (flip rate 0.1) is not available past 5" in capsys.readouterr().err


def test_past_five_objects_a_study_offers_only_the_exact_learners_settings_and_takes_up_to_ten(
        app_client: Any) -> None:
    refused = app_client.post("/api/v1/studies", json=seven_study(flip_rate=0.2, criterion="chance-constrained"),
                              headers=EXP)
    assert refused.status_code == 422
    errors = {e["field"]: e["message"] for e in refused.json()["errors"]}
    assert set(errors) == {"flip_rate", "criterion"}
    assert "expected 0 (the authors' learner) (7 objects given)" in errors["flip_rate"]
    ten = app_client.post("/api/v1/studies", json=lunch_study(objects=TEN_OBJECTS), headers=EXP)
    assert ten.status_code == 201, ten.text
    study = ten.json()
    assert [o["name"] for o in study["objects"]] == [o["name"] for o in TEN_OBJECTS]
    picture = app_client.get(f"/study/{study['id']}/goal/0.svg")
    assert picture.status_code == 200
    for name in ("lunch box", "saucer", "knife", "glass"):
        assert name in picture.text
    # Nine labels on Table B (the mug is forbidden: named under it): none covers another (a label moved off its
    # object has a line to it).
    tags = [tuple(float(v) for v in m) for m in re.findall(
        r'<rect x="([-\d.]+)" y="([-\d.]+)" width="([\d.]+)" height="([\d.]+)" rx="7" fill="#ffffff"', picture.text)]
    assert len(tags) == 9
    for i, (x, y, w, h) in enumerate(tags):
        for x2, y2, w2, h2 in tags[:i]:
            assert x + w <= x2 or x2 + w2 <= x or y + h <= y2 or y2 + h2 <= y, (x, y, x2, y2)
    assert picture.text.count("<line ") >= 1


FOUR_NAMES = ["lunch_box", "apple", "napkin", "spoon"]
FOUR_TRUTH = "F(lunch_box) & F(napkin) & F(spoon) & (!napkin U lunch_box)"


def _clear_learner_caches() -> None:
    """Forget every belief, view and plan remembered in this process (the learner path is about to change)."""
    from tableteach.core import learner_seam as seam
    from tableteach.core import session as core
    from tableteach.services import consistency, monitoring

    for cached in (monitoring.belief_view, monitoring.marginals_view, consistency.session_consistency,
                   core.next_step, seam.exact_belief_after, seam._exact_plan):
        cached.cache_clear()


@pytest.fixture
def exact_from_four(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The server's learner seam answers with the exact learner from four objects on (normally: past five)."""
    from tableteach.core import learner_seam as seam

    _clear_learner_caches()
    monkeypatch.setattr(seam, "ENUMERATED_UP_TO", 3)
    yield
    _clear_learner_caches()


def test_forced_onto_the_exact_path_a_four_object_study_agrees_with_the_enumerating_learner(
        exact_from_four: None, app_client: Any) -> None:
    from tableteach.core import learner_seam as seam
    from tableteach.core.puns import node_acceptance

    objects = [o for o in SEVEN_OBJECTS if o["name"] in FOUR_NAMES]
    spec = lunch_study(objects=objects, n_demonstrations=2, n_queries=3, n_tests=1,
                       tasks=[{"key": "custom", "ground_truth": FOUR_TRUTH}])
    study_id = open_spec(app_client, spec)
    token, state = to_teaching(app_client, study_id)
    h = bearer(token)
    for demonstration in (["lunch_box", "napkin", "spoon"], ["spoon", "lunch_box", "napkin", "apple"]):
        for obj in demonstration:
            assert app_client.post("/api/v1/me/placements", json={"object": obj}, headers=h).status_code == 200
        state = app_client.post("/api/v1/me/demonstration/finish", headers=h).json()
    while state["stage"] == "task":
        assert app_client.post("/api/v1/me/execution", headers=h).status_code == 200
        state = _until_finished(app_client, h)
        trace = state["execution"]["trace"]
        first = {obj: t for t, labels in reversed(list(enumerate(trace))) for obj in labels}
        verdict = {"lunch_box", "napkin", "spoon"} <= set(first) and first["lunch_box"] <= first["napkin"]
        state = app_client.post("/api/v1/me/assessment", json={"acceptable": verdict}, headers=h).json()
    files = _exports(app_client, study_id)
    beliefs, events = _rows(files, "beliefs.csv"), _rows(files, "events.csv")
    belief = app_client.get(f"/api/v1/studies/{study_id}/participants/1/belief", headers=EXP).json()["tasks"][0]
    assert belief["learner"] == "exact"

    # The same data through the enumerating learner: every number the exact path stored agrees to 1e-9.
    task = objects_task(tuple(FOUR_NAMES))
    space = get_domain(task).clause_space
    truth = space.mask_of_formula(FOUR_TRUTH)
    data: list[tuple[Any, bool, bool]] = []
    for row in beliefs:
        if row["record_kind"]:
            trace = tuple(frozenset(s) for s in json.loads(row["trace"]))
            acceptable = row["acceptable"] in ("True", "true")
            if row["record_kind"] == "query":
                before = seam.belief_after(task, PRIOR, 0.0, tuple(data), "enumerating")
                p = seam.verdict_probability(before, trace, acceptable)
                assert math.isclose(float(row["p_verdict"]), p, abs_tol=1e-9)
            data.append((trace, acceptable, row["record_kind"] == "query"))
        enumerated = seam.belief_after(task, PRIOR, 0.0, tuple(data), "enumerating")
        assert math.isclose(float(row["entropy"]), enumerated.entropy, abs_tol=1e-9)
        assert math.isclose(float(row["similarity"]), enumerated.similarity(truth), abs_tol=1e-9)
        assert math.isclose(float(row["top1_p"]), enumerated.map_probability, abs_tol=1e-9)
        exact_map = space.mask_of_formula(row["map_formula"])
        assert math.isclose(enumerated.belief.probs[enumerated.belief.space.find(exact_map)],
                            enumerated.map_probability, abs_tol=1e-9)  # a MAP (ties may pick another)
    final = seam.belief_after(task, PRIOR, 0.0, tuple(data), "enumerating")
    for m in belief["marginals"]:
        clause = next(c for c in space.clauses if c.text() == m["clause"])
        assert math.isclose(m["p"], final.marginals()[clause], abs_tol=1e-9)
    # The robot's executions: each query's P(acceptable) is the enumerated one of that execution, and the test
    # (min-regret) reaches the enumerated best P(acceptable) over every execution.
    started = [e for e in events if e["kind"] == "execution_started"]
    assert [e["step_kind"] for e in started] == ["query"] * 3 + ["test"]
    for k, e in enumerate(started):
        before = seam.belief_after(task, PRIOR, 0.0, tuple(data[: 2 + k]), "enumerating")
        trace = tuple(frozenset(s) for s in get_domain(task).trace_of(json.loads(e["robot_events"])))
        assert math.isclose(float(e["p_acceptable"]), before.p_acceptable(trace), abs_tol=1e-9)
    best = float(node_acceptance(final.belief).max())
    assert math.isclose(float(started[-1]["p_acceptable"]), best, abs_tol=1e-9)


def test_past_five_objects_the_robots_turn_is_planned_on_the_learner_thread_not_a_job_runner(
        app_client: Any) -> None:
    from tableteach.services.planning import Planner, step_of

    from ..waiting import wait_until
    from .test_planning import RecordingPlan

    plan = RecordingPlan()
    app_client.ctx.planner = Planner(plan)
    token, state = to_teaching(app_client, open_spec(app_client, seven_study(n_demonstrations=1)))
    h = bearer(token)
    for obj in DEMONSTRATIONS[0]:
        assert app_client.post("/api/v1/me/placements", json={"object": obj}, headers=h).status_code == 200
    state = app_client.post("/api/v1/me/demonstration/finish", headers=h).json()
    assert state["step"]["kind"] == "query"
    wait_until(lambda: bool(plan.calls), timeout=120, what="the query's plan")
    assert plan.calls[0][1].startswith("runtime-learner")  # job runners stay free for others' placements
    response = app_client.post("/api/v1/me/execution", headers=h)
    assert response.status_code == 200, response.text
    assert response.json()["execution"]["events"] == list(step_of(plan.calls[0][0]).robot_execution.events)
    assert len(plan.calls) == 1  # the request waited for (or found) the plan made ahead
