"""The dashboard's "what if" for one participant, the teacher-consistency flag, and a study that uses the
noise-aware learner: scripted teachers complete studies in-process, then the read endpoints and the exports are
checked against each other and against tableteach replay."""

from __future__ import annotations

import csv
import io
import json
import zipfile
from pathlib import Path
from typing import Any

import pytest

from tableteach.cli import main
from tableteach.services import participants as participants_service

from .helpers import EXP, FixedSessionSeeds, make_study, teach

@pytest.fixture(scope="module")
def studies(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Two Active studies the same teachers completed, one with the authors' learner and one noise-aware
    (flip_rate 0.2): every read the tests need, and each study's exports.zip."""
    from .conftest import in_process_app

    tmp = tmp_path_factory.mktemp("what-if")
    out: dict[str, Any] = {}
    # A participant's session seed is random; whether the learner the flipping teacher misled still plans tests
    # the truth accepts (whose flipped verdicts then raise the flag) depends on it, so the seeds are fixed here.
    with pytest.MonkeyPatch.context() as patch, in_process_app(tmp) as client:
        patch.setattr(participants_service, "secrets", FixedSessionSeeds())
        for name, flip in (("authors", None), ("noisy", 0.2)):
            extra = {} if flip is None else {"flip_rate": flip}
            study_id = make_study(client, ["active"], **extra)
            ids = teach(client, study_id)
            def get(path: str, study_id: str = study_id) -> Any:
                return client.get(f"/api/v1/studies/{study_id}{path}", headers=EXP)

            zipped = get("/exports/exports.zip")
            assert zipped.status_code == 200, zipped.text
            path = tmp / f"{name}.zip"
            path.write_bytes(zipped.content)
            out[name] = {
                "id": study_id, "ids": ids, "zip": path, "study": get("").json(), "live": get("/live").json(),
                "history": {pid: get(f"/participants/{pid}/history").json() for pid in ids},
                "what_if": {pid: get(f"/participants/{pid}/what-if?learner=flip%3D0.2&learner=data%3Ddemonstrations"
                                     "&learner=flip%3D0").json() for pid in ids},
            }
        bad = {case: client.get(f"/api/v1/studies/{out['authors']['id']}/participants/{out['authors']['ids'][0]}"
                                f"/what-if?{query}", headers=EXP)
               for case, query in (("unknown", "learner=flips%3D0.1"), ("flip", "learner=flip%3D0.5"),
                                   ("many", "&".join(f"learner=flip%3D0.0{i}" for i in range(1, 8))))}
        bad["participant"] = client.get(f"/api/v1/studies/{out['authors']['id']}/participants/999/what-if",
                                        headers=EXP)
        out["bad"] = {case: (r.status_code, r.json()) for case, r in bad.items()}
    return out


def beliefs(path: Path) -> list[dict[str, str]]:
    with zipfile.ZipFile(path) as archive:
        return list(csv.DictReader(io.StringIO(archive.read("beliefs.csv").decode())))


def learner(view: dict[str, Any], name: str) -> dict[str, Any]:
    (task,) = view["tasks"]
    return next(x for x in task["learners"] if x["learner"] == name)


@pytest.mark.parametrize("name", ["authors", "noisy"])
def test_the_study_learner_of_what_if_is_the_history_the_dashboard_shows(studies: dict[str, Any], name: str) -> None:
    s = studies[name]
    for pid in s["ids"]:
        (task,) = s["history"][pid]["tasks"]
        view = s["what_if"][pid]
        assert [x["learner"] for x in view["tasks"][0]["learners"]] == ["study", "flip=0.2", "data=demonstrations",
                                                                        "flip=0"]
        study = learner(view, "study")
        assert study["flip_rate"] == (0.2 if name == "noisy" else 0.0)
        assert len(study["steps"]) == len(task["steps"])
        for mine, shown in zip(study["steps"], task["steps"], strict=True):
            assert mine["similarity"] == pytest.approx(shown["similarity"], abs=1e-12)
            assert mine["entropy"] == pytest.approx(shown["entropy"], abs=1e-12)
            assert mine["map_formula"] == shown["map_formula"]


def test_other_learners_differ_where_they_should(studies: dict[str, Any]) -> None:
    s = studies["authors"]
    flipping = s["ids"][2]  # the teacher who flips every verdict
    view = s["what_if"][flipping]
    records = view["tasks"][0]["records"]
    queries = [k for k, kind in enumerate(records) if kind == "query"]
    assert records[0] is None and queries
    demos_only = learner(view, "data=demonstrations")["steps"]
    for k in queries:  # a demonstrations-only learner does not move at a query
        assert demos_only[k]["entropy"] == demos_only[k - 1]["entropy"]
    noisy, study = learner(view, "flip=0.2")["steps"], learner(view, "study")["steps"]
    assert any(abs(noisy[k]["entropy"] - study[k]["entropy"]) > 1e-6 for k in queries)
    # flip=0 in a study of the authors' learner is that learner
    assert learner(view, "flip=0")["steps"] == study
    # in the noise-aware study, flip=0 is the authors' learner and 'study' the noise-aware one
    noisy_study = studies["noisy"]["what_if"][studies["noisy"]["ids"][2]]
    assert learner(noisy_study, "flip=0")["flip_rate"] == 0.0
    assert learner(noisy_study, "study")["steps"] == learner(noisy_study, "flip=0.2")["steps"]


def test_bad_what_if_requests_say_what_was_wrong(studies: dict[str, Any]) -> None:
    bad = studies["bad"]
    assert bad["unknown"][0] == 422 and "unknown learner 'flips=0.1'" in bad["unknown"][1]["detail"]
    assert bad["flip"][0] == 422 and "flip must be a probability in [0, 0.5), got 0.5" in bad["flip"][1]["detail"]
    assert bad["many"][0] == 422 and "at most 6 learners" in bad["many"][1]["detail"]
    assert bad["participant"][0] == 404


@pytest.mark.parametrize("name", ["authors", "noisy"])
def test_consistency_in_the_live_table_history_and_exports_agree(studies: dict[str, Any], name: str) -> None:
    s = studies[name]
    live = {row["participant_id"]: row for row in s["live"]["participants"]}
    exported = {(r["participant_id"], r["step"]): r for r in beliefs(s["zip"])}
    for pid in s["ids"]:
        (task,) = s["history"][pid]["tasks"]
        c = task["consistency"]
        row = live[pid]["consistency"]
        assert row["tasks"][0]["score"] == pytest.approx(c["score"], abs=1e-12)
        assert row["flagged"] == c["flagged"] == (c["lowest"] < c["flag_below"])
        # each query's probability, as exported; each test's, from the probability the robot logged for its plan
        for step, p in enumerate(c["p_verdicts"]):
            cell = exported[(str(pid), str(step))]
            assert (cell["p_verdict"] == "") if p is None else float(cell["p_verdict"]) == pytest.approx(p, abs=1e-12)
            assert float(cell["consistency_score"]) == pytest.approx(c["score"], abs=1e-12)
            assert cell["consistency_flag"] == str(c["flagged"]).lower()
        tests = [x for x in task["executions"] if x["kind"] == "test"]
        assert [pytest.approx(x["p_acceptable"] if x["acceptable"] else 1 - x["p_acceptable"], abs=1e-9)
                for x in tests] == c["p_tests"]
        assert c["n_verdicts"] == len(tests) + sum(p is not None for p in c["p_verdicts"])


def test_the_teacher_who_flips_every_verdict_is_flagged_and_the_perfect_ones_are_not(studies: dict[str, Any]) -> None:
    live = {row["participant_id"]: row for row in studies["authors"]["live"]["participants"]}
    perfect_a, perfect_b, flipping = studies["authors"]["ids"]
    assert live[flipping]["consistency"]["flagged"]
    assert not live[perfect_a]["consistency"]["flagged"] and not live[perfect_b]["consistency"]["flagged"]
    assert live[flipping]["consistency"]["score"] < min(live[perfect_a]["consistency"]["score"],
                                                        live[perfect_b]["consistency"]["score"])


def test_a_noise_aware_study_learns_plans_and_exports_with_its_flip_rate(studies: dict[str, Any],
                                                                          tmp_path: Path, capsys) -> None:
    s = studies["noisy"]
    assert s["study"]["flip_rate"] == 0.2 and studies["authors"]["study"]["flip_rate"] == 0.0
    with zipfile.ZipFile(s["zip"]) as archive:
        assert json.loads(archive.read("study.json"))["flip_rate"] == 0.2
    out = tmp_path / "replay"
    assert main(["replay", str(s["zip"]), "--learner", "study", "--learner", "flip=0", "--out", str(out),
                 "--no-progress"]) == 0, capsys.readouterr().err
    with open(out / "replay.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    by = {(r["learner"], r["participant_id"], r["step"]): r for r in rows}
    exported = beliefs(s["zip"])
    for b in exported:  # the study's own settings (the noise-aware learner) reproduce beliefs.csv
        mine = by[("study", b["participant_id"], b["step"])]
        assert abs(float(mine["similarity"]) - float(b["similarity"])) < 1e-9
        assert abs(float(mine["entropy"]) - float(b["entropy"])) < 1e-9
        assert mine["map_formula"] == b["map_formula"]
    flipped = str(s["ids"][2])
    assert any(abs(float(by[("flip=0", flipped, b["step"])]["entropy"]) - float(b["entropy"])) > 1e-6
               for b in exported if b["participant_id"] == flipped and b["record_kind"] == "query")


@pytest.mark.parametrize("value, message", [
    (0.5, "must be a number below 0.5, got 0.5"), (-0.1, "must be a number of at least 0, got -0.1"),
    ("0.1", "must be a number"),
])
def test_a_flip_rate_outside_its_range_is_refused(app_client: Any, value: Any, message: str) -> None:
    from .conftest import study_spec

    response = app_client.post("/api/v1/studies", json=study_spec(["active"], flip_rate=value), headers=EXP)
    assert response.status_code == 422, response.text
    errors = {e["field"]: e["message"] for e in response.json()["errors"]}
    assert "flip_rate" in errors and message in errors["flip_rate"], errors
