"""One simulated run: the ground truth, the teachers' options, and the JSON worker protocol."""

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from tableteach.core.domain import get_domain
from tableteach.core.hypotheses import get_space
from tableteach.experiments.settings import DOMAINS, ExperimentSettings
from tableteach.experiments.simulate import COLUMNS, draw_truth, run_task_json, simulate_run, task_json

COL = {c: i for i, c in enumerate(COLUMNS)}


def test_study_tasks_use_their_fixed_ground_truth():
    for domain in ("dinner-task1", "dinner-task2"):
        settings = ExperimentSettings(domain=domain, runs=1, n_query=(1,), truth_sampler="fixed")
        rows = simulate_run(settings, 0)
        space = get_domain("dinner").clause_space
        expected = space.text_of(space.mask_of_formula(DOMAINS[domain][1]))
        assert {r[COL["ground_truth"]] for r in rows} == {expected}


def test_authors_sampler_draws_no_g_clauses():
    settings = ExperimentSettings(domain="synthetic", runs=1, truth_sampler="authors")
    space = get_space("synthetic", settings.prior)
    g_bits = sum(space.domain.clause_space.g_bit(p) for p in space.domain.forbiddable)
    truths = [draw_truth(settings, space, np.random.default_rng(i)) for i in range(30)]
    assert all(t & g_bits == 0 for t in truths) and len(set(truths)) > 5


def test_prior_sampler_draws_satisfiable_truths_with_g_clauses():
    settings = ExperimentSettings(domain="dinner-random", runs=1, prior="chains-2020")
    space = get_space("dinner", "chains-2020")
    g_bits = sum(space.domain.clause_space.g_bit(p) for p in space.domain.forbiddable)
    truths = [draw_truth(settings, space, np.random.default_rng(i)) for i in range(30)]
    assert any(t & g_bits for t in truths)
    # SimulatedTeacher refuses an unsatisfiable truth, so complete runs show the draws were satisfiable
    settings_run = replace(settings, runs=3, n_query=(1,))
    for run in range(3):
        assert len(simulate_run(settings_run, run)) == 3 * 4


def test_a_perfect_teacher_on_task1_leads_active_to_the_truth():
    settings = ExperimentSettings(domain="dinner-task1", runs=1, n_query=(6,), truth_sampler="fixed")
    rows = simulate_run(settings, 0)
    final = [r for r in rows if r[COL["protocol"]] == "active"][-1]
    first = [r for r in rows if r[COL["protocol"]] == "active"][0]
    assert final[COL["similarity"]] > first[COL["similarity"]]
    assert final[COL["entropy"]] < first[COL["entropy"]]


def test_noise_changes_assessments_only():
    base = ExperimentSettings(domain="dinner-task2", runs=1, n_query=(6,), truth_sampler="fixed")
    clean, noisy = simulate_run(base, 0), simulate_run(replace(base, noise=0.5), 0)
    assert [r[:-1] for r in clean[:3]] == [r[:-1] for r in noisy[:3]]  # prior and the shared demonstrations
    batch = [r[:-1] for r in clean if r[COL["protocol"]] == "batch"]
    assert batch == [r[:-1] for r in noisy if r[COL["protocol"]] == "batch"]  # demonstrations are never noisy
    assert [r[:-1] for r in clean] != [r[:-1] for r in noisy]


def test_uniform_demonstrations_differ_from_optimal_ones():
    base = ExperimentSettings(domain="dinner-random", runs=1, n_query=(4,))
    optimal = simulate_run(base, 0)
    uniform = simulate_run(replace(base, demo_mode="uniform"), 0)
    assert optimal[0][COL["ground_truth"]] == uniform[0][COL["ground_truth"]]
    assert [r[COL["entropy"]] for r in optimal] != [r[COL["entropy"]] for r in uniform]


def test_defaults_are_the_authors_demonstrator_metric_and_ties():
    settings = ExperimentSettings()
    assert (settings.demo_mode, settings.similarity, settings.query_ties) == ("required-only", "authors", "uniform")


def test_test_success_is_measured_at_final_steps_only_and_changes_nothing_else():
    base = ExperimentSettings(domain="dinner-random", runs=1, n_query=(1, 3))
    plain, tested = simulate_run(base, 0), simulate_run(replace(base, test_success=True), 0)
    col = COL["test_success"]
    assert {r[col] for r in plain} == {""}
    assert [r[:col] for r in plain] == [r[:col] for r in tested]  # same learning: its own random stream
    for r in tested:
        final = r[COL["n_executions"]] in (3, 5)
        assert (r[col] in (0, 1)) if final else r[col] == ""


def test_the_metric_changes_similarities_only():
    base = ExperimentSettings(domain="dinner-task2", runs=1, n_query=(4,), truth_sampler="fixed")
    rows, strict = simulate_run(base, 0), simulate_run(replace(base, similarity="strict"), 0)
    assert [r[COL["entropy"]] for r in rows] == [r[COL["entropy"]] for r in strict]  # the same learning
    assert [r[COL["similarity"]] for r in rows] != [r[COL["similarity"]] for r in strict]


def test_tie_breaking_changes_which_queries_are_asked():
    base = ExperimentSettings(domain="dinner-random", runs=5, n_query=(4,))
    entropies = [[r[COL["entropy"]] for r in simulate_run(replace(base, query_ties=ties), run)]
                 for ties in ("uniform", "shortest") for run in range(5)]
    assert entropies[:5] != entropies[5:]


def test_run_task_json_rejects_a_run_outside_the_sweep():
    settings = ExperimentSettings(domain="dinner-random", runs=2, n_query=(0,))
    with pytest.raises(ValueError, match=r"in \[0, 2\), got 2"):
        run_task_json(task_json(settings, 2))


def test_worker_process_answers_json_lines_and_survives_a_bad_task():
    settings = ExperimentSettings(domain="dinner-random", runs=2, n_query=(0,))
    stdin = "not json\n" + task_json(settings, 1) + "\n"
    out = subprocess.run([sys.executable, "-m", "tableteach.experiments.worker"], input=stdin,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    first, second = (json.loads(line) for line in out.stdout.splitlines())
    assert first["run"] is None and first["error"].startswith("JSONDecodeError")
    assert second["run"] == 1
    expected = json.loads(run_task_json(task_json(settings, 1)))["rows"]
    assert [r[:-1] for r in second["rows"]] == [r[:-1] for r in expected]
