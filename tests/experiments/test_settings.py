"""Experiment settings: parsing and validation."""

import pytest

from tableteach.experiments.settings import ExperimentSettings, parse_n_query, resolve_truth_sampler


@pytest.mark.parametrize("text, expected", [("1,2,3", (1, 2, 3)), ("1-6", (1, 2, 3, 4, 5, 6)),
                                            ("0, 2-4, 3", (0, 2, 3, 4)), ("5", (5,))])
def test_parse_n_query(text, expected):
    assert parse_n_query(text) == expected


@pytest.mark.parametrize("text, message", [("-1", "must be >= 0"), ("1,x", "'x' is not a whole number"),
                                           ("", "'' is not a whole number")])
def test_parse_n_query_rejects(text, message):
    with pytest.raises(ValueError, match=message):
        parse_n_query(text)


@pytest.mark.parametrize("kwargs, message", [
    ({"domain": "kitchen"}, "unknown domain 'kitchen'; expected one of synthetic, dinner-task1"),
    ({"runs": 0}, "runs must be a whole number >= 1, got 0"),
    ({"n_query": (2, 1)}, "distinct and increasing"),
    ({"n_query": ()}, "at least one value"),
    ({"prior": "flat"}, "unknown prior 'flat'"),
    ({"demo_mode": "lazy"}, "unknown demonstration mode 'lazy'"),
    ({"domain": "dinner-task2", "truth_sampler": "prior"}, "has a fixed ground truth"),
    ({"truth_sampler": "fixed"}, "ground truths are drawn per run"),
    ({"noise": -0.1}, r"noise must be a probability in \[0, 1\]"),
    ({"noise": 1.5}, r"noise must be a probability in \[0, 1\], got 1.5"),
    ({"similarity": "jaccard"}, "unknown similarity metric 'jaccard'; expected one of authors, strict"),
    ({"query_ties": "first"}, "unknown query tie-breaking 'first'; expected one of uniform, shortest"),
    ({"test_success": "yes"}, "test_success must be true or false"),
])
def test_settings_reject(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ExperimentSettings(**kwargs)


def test_settings_round_trip_through_json():
    settings = ExperimentSettings(domain="dinner-random", runs=7, n_query=(0, 3), seed=9, truth_sampler="authors",
                                  demo_mode="uniform", noise=0.1, similarity="strict", query_ties="shortest",
                                  test_success=True)
    assert ExperimentSettings.from_json(settings.to_json()) == settings


def test_fixed_truth_domains_resolve_to_the_fixed_sampler():
    assert resolve_truth_sampler("dinner-task1", None) == "fixed"
    assert resolve_truth_sampler("synthetic", None) == "prior"
    assert resolve_truth_sampler("dinner-random", "authors") == "authors"
    with pytest.raises(ValueError, match="ground truth is fixed"):
        resolve_truth_sampler("dinner-task1", "prior")


def test_synthetic_size_is_a_setting_with_the_papers_default():
    from tableteach.experiments.settings import ExperimentSettings

    assert (ExperimentSettings().n_waypoints, ExperimentSettings().n_threats) == (5, 5)
    assert ExperimentSettings(n_waypoints=4, n_threats=6).to_json()["n_threats"] == 6


@pytest.mark.parametrize("sizes, message", [
    ({"n_waypoints": 11}, "the exact learner takes 2 to 10"),
    ({"n_waypoints": 8, "n_threats": 11}, "n_threats 11"),
    ({"n_waypoints": 8, "n_threats": 8, "similarity": "strict"}, "similarity 'strict' is not offered past enumeration"),
    ({"n_waypoints": 5, "n_threats": 9, "demo_mode": "uniform"}, "demo_mode 'uniform' is not offered"),
    ({"n_waypoints": 6, "prior": "forest"}, "prior structure 'forest'"),
    ({"n_waypoints": 1}, "n_waypoints must be a whole number >= 2"),
    ({"domain": "dinner-task1", "truth_sampler": "fixed", "n_waypoints": 4}, "has its own objects"),
])
def test_bad_synthetic_sizes_are_named(sizes, message):
    from tableteach.experiments.settings import ExperimentSettings

    with pytest.raises(ValueError, match=message):
        ExperimentSettings(**sizes)


def test_a_smaller_synthetic_run_uses_its_own_propositions():
    from tableteach.experiments.settings import ExperimentSettings
    from tableteach.experiments.simulate import experiment_space, simulate_run

    settings = ExperimentSettings(n_waypoints=3, n_threats=2, runs=1, n_query=(1,))
    space = experiment_space(settings)
    assert space.domain.propositions == ("w0", "w1", "w2", "t0", "t1")
    rows = simulate_run(settings, 0)
    assert rows and all(0.0 <= row[9] <= 1.0 for row in rows)  # similarity column


def test_past_enumeration_the_exact_learner_runs_the_sweep():
    from tableteach.experiments.exact_run import simulate_exact_run
    from tableteach.experiments.settings import ExperimentSettings
    from tableteach.experiments.simulate import simulate_run

    assert ExperimentSettings(n_waypoints=8, n_threats=8).exact_learner
    assert ExperimentSettings(n_waypoints=5, n_threats=9).exact_learner
    assert not ExperimentSettings().exact_learner
    settings = ExperimentSettings(n_waypoints=6, n_threats=2, runs=1, n_query=(1, 2), test_success=True)
    rows = simulate_run(settings, 0)
    assert len(rows) == 3 * (4 + 5)  # protocols x (prior, 2 demonstrations, 1 or 2 more)
    assert all(0.0 <= row[9] <= 1.0 and 0.0 <= row[10] <= 1.0 and row[8] >= 0 for row in rows)
    assert {row[4] for row in rows} == {"active", "random", "batch"}
    finals = [row for row in rows if row[7] == 2 + row[5]]
    assert all(row[13] in (0, 1) for row in finals)
    again = simulate_exact_run(settings, 0)
    assert [row[:14] for row in again] == [row[:14] for row in rows]  # all but the seconds


def test_the_exact_sweep_agrees_with_the_enumerated_one_where_both_run():
    """Truth-free numbers (the prior's entropy) agree; the rest differ only by the truth's draw."""
    from tableteach.experiments.exact_run import simulate_exact_run
    from tableteach.experiments.settings import ExperimentSettings
    from tableteach.experiments.simulate import simulate_run

    settings = ExperimentSettings(n_waypoints=3, n_threats=2, runs=1, n_query=(1,))
    exact = simulate_exact_run(settings, 0)
    enumerated = simulate_run(settings, 0)
    assert exact[0][6] == enumerated[0][6] == "prior"
    assert exact[0][8] == pytest.approx(enumerated[0][8], abs=1e-9)


def test_exact_demonstrations_are_the_required_items_in_a_valid_uniform_order():
    import numpy as np

    from tableteach.core.exact.mapping import Formula
    from tableteach.experiments.exact_run import _demonstration, _start

    domain, prior = _start(6, 2, "chains-2020-sat")
    truth = Formula(((0, 1, 2), (3,), (4,), (5,)), 0, 1 << 3, 1)  # w0 before w1 before w2; w3 required; G(!t0)
    rng = np.random.default_rng(0)
    seen = [tuple(_demonstration(domain, prior, truth, rng).events) for _ in range(400)]
    # w2 is neither required nor an antecedent: a demonstration never visits it (the authors' demonstrator)
    expected = {("w3", "w0", "w1"), ("w0", "w3", "w1"), ("w0", "w1", "w3")}
    assert set(seen) == expected
    assert min(seen.count(order) for order in expected) > 90  # 133 each expected
