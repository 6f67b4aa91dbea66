"""Studies with their own objects through the REST API: every bad definition is refused naming the problem, a
participant teaches one to completion, and the state, goal picture, exports and codebook carry its objects."""

from __future__ import annotations

import copy
import csv
import io
import json
import zipfile
from typing import Any

from tableteach.core.domain import get_domain, objects_task

from ..study_objects import EIGHT_OBJECTS, LUNCH_OBJECTS, LUNCH_TRUTH, lunch_study
from .helpers import EXP, bearer, open_spec, to_teaching

NAMES = [o["name"] for o in LUNCH_OBJECTS]


def _refused(client: Any, spec: dict[str, Any]) -> dict[str, str]:
    response = client.post("/api/v1/studies", json=spec, headers=EXP)
    assert response.status_code == 422, response.text
    return {e["field"]: e["message"] for e in response.json()["errors"]}


def _objects(change: Any) -> list[dict[str, Any]]:
    objects = copy.deepcopy(LUNCH_OBJECTS)
    change(objects)
    return objects


def test_each_bad_definition_of_objects_is_refused_naming_the_problem(app_client: Any) -> None:
    too_many = [{**o, "name": f"{o['name']}_{i}"} for i in range(3) for o in LUNCH_OBJECTS[:4]][:11]
    errors = _refused(app_client, lunch_study(objects=too_many))
    assert "at most 10" in errors["objects"]
    assert "at least 2" in _refused(app_client, lunch_study(objects=LUNCH_OBJECTS[:1]))["objects"]
    six_to_ten = _refused(app_client, lunch_study(objects=EIGHT_OBJECTS, flip_rate=0.1, criterion="most-likely",
                                                  prior="forest"))
    assert six_to_ten["flip_rate"].startswith("the noise-aware learner (flip rate 0.1) is not available past 5 objects")
    assert "(8 objects given)" in six_to_ten["flip_rate"]
    assert "'most-likely' is not available past 5 objects; expected min-regret" in six_to_ten["criterion"]
    assert "'forest' has no exact factorised form" in six_to_ten["prior"]

    def twice(objects: list[dict[str, Any]]) -> None:
        objects[3]["name"] = "apple"

    assert _refused(app_client, lunch_study(objects=_objects(twice)))["objects.3.name"] == (
        "'apple' is already the name of object 2; each object needs its own name")

    def invalid(objects: list[dict[str, Any]]) -> None:
        objects[0]["name"] = "Lunch Box"
        objects[1]["name"] = "true"

    errors = _refused(app_client, lunch_study(objects=_objects(invalid)))
    assert "lower-case letters, digits and _" in errors["objects.0.name"] and "Lunch Box" in errors["objects.0.name"]
    assert "a word of the formula language" in errors["objects.1.name"]

    def odd(objects: list[dict[str, Any]]) -> None:
        objects[0]["shape"] = "teapot"
        objects[1]["colour"] = "red"
        objects[2]["size"] = 40

    errors = _refused(app_client, lunch_study(objects=_objects(odd)))
    assert "plate, bowl, cup, glass, utensil or box" in errors["objects.0.shape"]
    assert "#rrggbb" in errors["objects.1.colour"]
    assert errors["objects.2.size"] == "a plate's diameter must be 12 to 28 cm, got 40"

    unknown = lunch_study(tasks=[{"key": "custom", "ground_truth": "F(banana) & (!apple U lunch_box)"}])
    message = _refused(app_client, unknown)["tasks.0.ground_truth"]
    assert "it names banana, which is not an object of this study" in message
    assert "lunch_box, apple, napkin, spoon, mug" in message
    dinner_task = _refused(app_client, lunch_study(tasks=[{"key": "task1"}]))
    assert "task1 is the dinner table's task" in dinner_task["tasks.0.key"]


def test_a_goal_layout_off_the_table_overlapping_or_out_of_reach_is_refused_naming_the_object(app_client: Any) -> None:
    def far(objects: list[dict[str, Any]]) -> None:
        objects[4]["slot"] = {"x": -18, "y": -15}  # the far left corner, away from the robot

    message = _refused(app_client, lunch_study(objects=_objects(far)))["objects.4.slot"]
    assert message.startswith("the arm cannot reach the mug at its place at x -18, y -15 cm")
    assert "move it towards the robot" in message

    def overlapping(objects: list[dict[str, Any]]) -> None:
        objects[2]["slot"] = {"x": 3, "y": 4}

    message = _refused(app_client, lunch_study(objects=_objects(overlapping)))["objects.2.slot"]
    assert "the napkin's place overlaps the lunch box's" in message

    def off(objects: list[dict[str, Any]]) -> None:
        objects[0]["slot"] = {"x": 20, "y": 0}

    message = _refused(app_client, lunch_study(objects=_objects(off)))["objects.0.slot"]
    assert "the lunch box would hang over Table B's edge" in message and "x must lie within ±17 cm" in message
    crowded = [{"name": f"plate_{i}", "shape": "plate", "size": 12, "colour": "#ffffff",
                "slot": {"x": -12 + 13 * (i % 3), "y": -8 + 15 * (i // 3)}} for i in range(5)]
    crowded[0].update(shape="box", size=14)
    crowded[4].update(shape="plate", size=28, slot={"x": 0, "y": 0})
    errors = _refused(app_client, lunch_study(objects=crowded, tasks=[{"key": "none"}]))
    assert any("overlaps" in m or "Table A" in m for m in errors.values())


def test_a_study_with_its_own_objects_is_stored_and_given_back_as_its_definition(app_client: Any) -> None:
    created = app_client.post("/api/v1/studies", json=lunch_study(), headers=EXP)
    assert created.status_code == 201, created.text
    study = created.json()
    assert [o["name"] for o in study["objects"]] == NAMES
    assert study["objects"][0] == {"name": "lunch_box", "shape": "box", "colour": "#c0392b", "size": 12.0,
                                   "slot": {"x": 0.0, "y": 2.0}}
    task = study["tasks"][0]
    space = get_domain(objects_task(tuple(NAMES))).clause_space
    assert task["ground_truth"] == space.text_of(space.mask_of_formula(LUNCH_TRUTH))
    assert "lunch box" in task["instructions"].lower()
    spec = app_client.get(f"/api/v1/studies/{study['id']}/spec", headers=EXP).json()
    assert spec["objects"] == study["objects"]
    clone = app_client.post(f"/api/v1/studies/{study['id']}/clone", headers=EXP)
    assert clone.status_code == 201 and clone.json()["objects"] == study["objects"]
    dinner = app_client.post("/api/v1/studies", json={"tasks": [{"key": "task1"}]}, headers=EXP).json()
    assert dinner["objects"] is None
    assert app_client.get(f"/api/v1/studies/{dinner['id']}/spec", headers=EXP).json()["objects"] is None
    described = app_client.get("/api/v1/formulas/describe", params={"formula": "F(apple) & G(!mug)",
                                                                    "objects": ",".join(NAMES)}, headers=EXP)
    assert described.status_code == 200 and described.json()["formula"] == "G(!mug) & F(apple)"


def _teach(client: Any, study_id: str) -> tuple[str, dict[str, Any]]:
    """A participant's whole session: a demonstration of the truth, a verdict on the query, the test, the
    questionnaire; the token and the last state."""
    token, state = to_teaching(client, study_id)
    h = bearer(token)
    assert state["objects"] == NAMES
    assert state["task"]["goal_picture"] == f"/study/{study_id}/goal/0.svg"
    assert sorted(state["task"]["required"]) == ["lunch_box", "napkin", "spoon"]
    wrong = client.post("/api/v1/me/placements", json={"object": "fork"}, headers=h)
    assert wrong.status_code == 422 and wrong.json()["detail"] == (
        "object: 'fork' is not an object of this study; expected one of lunch_box, apple, napkin, spoon, mug")
    for obj in ("lunch_box", "spoon", "napkin"):
        assert client.post("/api/v1/me/placements", json={"object": obj}, headers=h).status_code == 200
    state = client.post("/api/v1/me/demonstration/finish", headers=h).json()
    while state["stage"] == "task":
        assert state["step"]["kind"] in ("query", "test"), state["step"]
        started = client.post("/api/v1/me/execution", headers=h).json()
        state = _until_finished(client, h, started)
        events = state["execution"]["events"]
        assert set(events) <= set(NAMES)
        trace = [frozenset(s) for s in state["execution"]["trace"]]
        response = client.post("/api/v1/me/assessment", json={"acceptable": _satisfies(trace)}, headers=h)
        assert response.status_code == 200, response.text
        state = response.json()
    assert state["stage"] == "questionnaire"
    done = client.post("/api/v1/me/questionnaire", json={"answers": {"learned": 4}}, headers=h)
    assert done.status_code == 200 and done.json()["stage"] == "done"
    return token, done.json()


def _satisfies(trace: list[frozenset[str]]) -> bool:
    """The lunch truth on a trace: box, napkin, spoon placed, the box before the napkin, never the mug."""
    first = {}
    for t, state in enumerate(trace):
        for obj in state:
            first.setdefault(obj, t)
    return ({"lunch_box", "napkin", "spoon"} <= set(first) and "mug" not in first
            and first["lunch_box"] <= first["napkin"])


def _until_finished(client: Any, h: dict[str, str], state: dict[str, Any]) -> dict[str, Any]:
    from ..waiting import wait_until

    latest = {"state": state}

    def finished() -> bool:
        latest["state"] = client.get("/api/v1/me", headers=h).json()
        return latest["state"]["execution"]["status"] == "finished"

    wait_until(finished, timeout=300, what="the robot's execution to finish")
    return latest["state"]


def test_a_participant_teaches_a_study_with_its_own_objects_and_the_exports_carry_them(app_client: Any) -> None:
    study_id = open_spec(app_client, lunch_study())
    _token, done = _teach(app_client, study_id)
    learned = done["completion"]["learned"][0]
    assert set(learned["map_formula"].replace("(", " ").replace(")", " ").replace("!", " ").split()) - {
        "F", "G", "U", "&"} <= set(NAMES)
    picture = app_client.get(f"/study/{study_id}/goal/0.svg")
    assert picture.status_code == 200 and picture.headers["content-type"].startswith("image/svg+xml")
    assert "Pack the lunch box" in picture.text and "Never place: mug" in picture.text
    assert "apple (optional)" in picture.text and "lunch box" in picture.text
    assert app_client.get(f"/study/{study_id}/goal/1.svg").status_code == 404

    exported = app_client.get(f"/api/v1/studies/{study_id}/exports/exports.zip", headers=EXP)
    assert exported.status_code == 200
    files = zipfile.ZipFile(io.BytesIO(exported.content))
    study = json.loads(files.read("study.json"))
    assert [o["name"] for o in study["objects"]] == NAMES
    codebook = list(csv.DictReader(io.StringIO(files.read("codebook.csv").decode())))
    objects_row = next(r for r in codebook if r["file"] == "events.csv" and r["column"] == "object")
    assert objects_row["units_or_levels"] == "lunch_box, apple, napkin, spoon, mug"
    described = {r["column"]: r["meaning"] for r in codebook if r["file"] == "study.json"}
    assert "a cup of diameter 8 cm, colour #2e86c1, its place on Table B at x 13 cm, y 10 cm" in (
        described["objects where name = mug"])
    events = list(csv.DictReader(io.StringIO(files.read("events.csv").decode())))
    assert {e["object"] for e in events if e["kind"] == "place"} == {"lunch_box", "spoon", "napkin"}
    beliefs = list(csv.DictReader(io.StringIO(files.read("beliefs.csv").decode())))
    assert beliefs and all(b["similarity"] for b in beliefs)
    history = app_client.get(f"/api/v1/studies/{study_id}/participants/1/belief", headers=EXP)
    assert history.status_code == 200 and "lunch box" in history.text


def test_tableteach_teach_teaches_a_study_with_its_own_objects_and_refuses_a_formula_over_others(
        shared_server: Any) -> None:
    import subprocess
    import sys

    from .conftest import EXPERIMENTER_TOKEN, open_study

    study = open_study(shared_server.url, lunch_study())
    command = [sys.executable, "-m", "tableteach.cli", "teach", "--server", shared_server.url, "--study", study]
    done = subprocess.run([*command, "--ground-truth", LUNCH_TRUTH, "--token", EXPERIMENTER_TOKEN, "--seed", "4"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["completion_code"] and summary["final"][0]["similarity"] > 0
    robot = {obj for execution in summary["executions"] for obj in execution["events"]}
    assert robot <= set(NAMES) and summary["final"][0]["map_formula"]
    refused = subprocess.run([*command, "--ground-truth", "task1", "--token", EXPERIMENTER_TOKEN],
                             capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr
    assert "--ground-truth 'task1'" in refused.stderr and "lunch_box" in refused.stderr
    without_token = subprocess.run([*command, "--ground-truth", "F(bowl)"], capture_output=True, text=True,
                                   timeout=300)
    assert without_token.returncode == 2 and "the study's objects are lunch_box, apple, napkin, spoon, mug" in (
        without_token.stderr)


def test_tableteach_replay_reproduces_the_beliefs_of_a_study_with_its_own_objects(app_client: Any, tmp_path: Any,
                                                                                   capsys: Any) -> None:
    from tableteach.cli import main

    study_id = open_spec(app_client, lunch_study())
    _teach(app_client, study_id)
    archive = tmp_path / "exports.zip"
    archive.write_bytes(app_client.get(f"/api/v1/studies/{study_id}/exports/exports.zip", headers=EXP).content)
    code = main(["replay", str(archive), "--learner", "study", "--out", str(tmp_path / "replay"), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    with open(tmp_path / "replay" / "replay.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(r["map_formula"] == r["study_map_formula"] for r in rows)
    assert all(abs(float(r["similarity"]) - float(r["study_similarity"])) < 1e-9 for r in rows)
