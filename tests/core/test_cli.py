"""The command-line contract that other tools rely on."""

import json
import subprocess
import sys

import pytest

from ..conftest import AUTHORS_DATA, REPO

DEMOS = REPO / "examples" / "dinner_demos.json"


def tableteach(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "tableteach.cli", *args], capture_output=True, text=True,
                          timeout=120)


def test_infer_prints_the_documented_json():
    out = tableteach("infer", "--task", "dinner", "--prior", "chains-2020", "--data", str(DEMOS), "--top", "3")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert set(result) >= {"support", "entropy", "map", "n_hypotheses", "seconds"}
    assert result["n_hypotheses"] == 513_024
    probs = [s["p"] for s in result["support"]]
    assert len(probs) == 3 and probs == sorted(probs, reverse=True)
    assert result["map"] == result["support"][0]["formula"]
    for clause in result["support"][0]["clauses"]:
        assert clause.startswith(("G(!", "F(", "(!"))


@pytest.mark.parametrize("command, extra", [("query", ["--strategy", "active", "--seed", "1"]),
                                             ("query", ["--strategy", "random", "--seed", "1"]),
                                             ("plan", ["--criterion", "most-likely"])])
def test_query_and_plan_print_an_execution(command, extra):
    out = tableteach(command, "--task", "dinner", "--data", str(DEMOS), *extra)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert set(result) == {"execution", "p_acceptable", "seconds"}
    assert len(set(result["execution"])) == len(result["execution"])
    assert 0.0 <= result["p_acceptable"] <= 1.0


def test_reads_the_authors_format():
    out = tableteach("infer", "--task", "dinner", "--prior", "chains-2020", "--authors-format",
                     "--data", str(AUTHORS_DATA / "batch_2020_server"), "--top", "3")
    assert out.returncode == 0, out.stderr
    probs = [s["p"] for s in json.loads(out.stdout)["support"]]
    assert probs[0] == pytest.approx(probs[2], abs=1e-12)


@pytest.mark.parametrize(
    "content, message",
    [
        ('{"executions": [', "not valid JSON"),
        ('{"executions": [{"trace": [[], ["spoon"]], "label": true}]}', "unknown proposition(s) spoon"),
        ('{"executions": [{"trace": [], "label": true}]}', "non-empty list of states"),
        ('{"executions": [{"trace": [[]], "label": "yes"}]}', "expected true or false"),
        ('{"runs": []}', "list 'executions'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, content, message):
    data = tmp_path / "data.json"
    data.write_text(content)
    out = tableteach("infer", "--task", "dinner", "--data", str(data))
    assert out.returncode == 2
    assert out.stdout == ""
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in out.stderr


def test_unknown_task_is_one_line_and_exit_2():
    out = tableteach("infer", "--task", "kitchen", "--data", str(DEMOS))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert "kitchen" in out.stderr


def test_synthetic_domain_end_to_end(tmp_path):
    data = tmp_path / "synthetic.json"
    data.write_text('{"executions": [{"trace": [[], ["w1"], ["w1"], ["w0"], ["w3"]], "label": true}]}')
    out = tableteach("plan", "--task", "synthetic", "--data", str(data), "--seed", "2")
    assert out.returncode == 0, out.stderr
    plan = json.loads(out.stdout)
    assert plan["p_acceptable"] == pytest.approx(1.0)
    assert not any(p.startswith("t") for p in plan["execution"])  # threats are never needed


SIX_OBJECTS = "plate,bowl,cup,fork,knife,glass"


def _objects_data(tmp_path):
    data = {"executions": [
        {"trace": [[], ["plate"], ["plate", "bowl"], ["plate", "bowl", "cup"]], "label": True},
        {"trace": [[], ["plate"], ["plate", "cup"], ["plate", "cup", "bowl"]], "label": True},
        {"trace": [[], ["cup"]], "label": False},
    ]}
    path = tmp_path / "six.json"
    path.write_text(json.dumps(data))
    return path


def test_objects_past_five_use_the_factorised_learner(tmp_path):
    path = _objects_data(tmp_path)
    out = tableteach("infer", "--objects", SIX_OBJECTS, "--data", str(path), "--top", "4")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout)
    assert set(result) >= {"support", "entropy", "map", "n_hypotheses", "seconds", "marginals"}
    assert result["entropy"] > 0
    probs = [m["p"] for m in result["marginals"]]
    assert len(probs) == 4 and probs == sorted(probs, reverse=True)
    assert result["marginals"][0]["clause"] in ("F(plate)", "F(bowl)")  # both demonstrations placed them
    assert result["map"] == result["support"][0]["formula"] and "F(plate)" in result["map"]
    assert 0 < result["support"][0]["p"] <= 1 and result["n_hypotheses"] is None
    plan = json.loads(tableteach("plan", "--objects", SIX_OBJECTS, "--data", str(path)).stdout)
    assert plan["execution"][0] == "plate" and set(plan) == {"execution", "p_acceptable", "seconds"}


def test_objects_up_to_five_are_enumerated(tmp_path):
    path = tmp_path / "two.json"
    path.write_text(json.dumps({"executions": [{"trace": [[], ["a"], ["a", "b"]], "label": True}]}))
    result = json.loads(tableteach("infer", "--objects", "a,b", "--data", str(path)).stdout)
    assert result["map"] == result["support"][0]["formula"]


@pytest.mark.parametrize("objects, message", [
    ("a", "1 names given; expected 2 to 10"),
    ("a,b,c,d,e,f,g,h,i,j,k", "11 names given"),
    ("a,b,a", "a named more than once"),
    ("a,Bowl", "'Bowl' is not a valid object name"),
    ("a,F", "'F' is not a valid object name"),
])
def test_bad_objects_are_one_line_and_exit_2(tmp_path, objects, message):
    out = tableteach("infer", "--objects", objects, "--data", str(_objects_data(tmp_path)))
    assert out.returncode == 2 and message in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_data_naming_other_objects_is_refused(tmp_path):
    out = tableteach("infer", "--objects", "plate,bowl", "--data", str(_objects_data(tmp_path)))
    assert out.returncode == 2 and "unknown proposition(s) cup" in out.stderr


def test_task_and_objects_exclude_each_other(tmp_path):
    out = tableteach("infer", "--task", "dinner", "--objects", "a,b", "--data", str(_objects_data(tmp_path)))
    assert out.returncode == 2 and "exactly one of --task" in out.stderr
