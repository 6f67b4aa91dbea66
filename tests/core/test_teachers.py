"""The simulated teacher's demonstrators, above all the authors' required-only demonstrator."""

from itertools import permutations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tableteach.core.domain import get_domain
from tableteach.core.hypotheses import get_space
from tableteach.core.ltl_semantics import evaluate
from tableteach.core.teachers import DEMO_MODES, SimulatedTeacher, authors_ground_truth, sample_ground_truth

SPACES = {name: get_space(name, "chains-2020-sat") for name in ("dinner", "synthetic")}


def truth_of(domain_name: str, sampler: str, seed: int) -> int:
    rng = np.random.default_rng(seed)
    if sampler == "authors":
        return authors_ground_truth(get_domain(domain_name), rng)
    return sample_ground_truth(SPACES[domain_name], rng)


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(["dinner", "synthetic"]), st.sampled_from(["prior", "authors"]), st.integers(0, 2**31))
def test_required_only_demos_are_the_required_items_in_every_valid_order(domain_name, sampler, seed):
    domain = get_domain(domain_name)
    space = domain.clause_space
    truth = truth_of(domain_name, sampler, seed)
    formula = space.formula_of(truth)
    clauses = space.clauses_of(truth)
    required = {c.first for c in clauses if c.kind == "F"} | {c.first for c in clauses if c.kind == "U"}
    # brute force, by the general LTL semantics: the orders of the required set that satisfy the truth
    valid = {order for order in permutations(sorted(required)) if evaluate(formula, domain.trace_of(order))}
    assert valid, f"a satisfiable truth has a valid order: {space.text_of(truth)}"
    teacher = SimulatedTeacher(domain, truth)  # the default mode
    rng = np.random.default_rng(seed)
    seen = set()
    for _ in range(30 * len(valid)):
        demo = teacher.demonstrate(rng)
        assert evaluate(formula, list(demo.trace))  # satisfies the truth (the trace includes failed moves)
        assert len(demo.events) == len(set(demo.events)) and set(demo.events) == required  # nothing else
        seen.add(demo.events)
    assert seen == valid  # every valid order is reachable (30 draws per order: a miss has odds ~ n e^-30)


def test_required_only_is_the_default_and_never_shows_optional_or_forbidden_items():
    domain = get_domain("dinner")
    truth = domain.clause_space.mask_of_formula("G(!small_plate) & F(dinner_plate) & F(bowl) & (!bowl U dinner_plate)")
    teacher = SimulatedTeacher(domain, truth)
    assert teacher.demo_mode == "required-only" == DEMO_MODES[0]
    rng = np.random.default_rng(1)
    assert {teacher.demonstrate(rng).events for _ in range(20)} == {("dinner_plate", "bowl")}
    optimal = SimulatedTeacher(domain, truth, demo_mode="optimal")  # the named alternative shows extras
    assert any({"knife", "fork"} & set(optimal.demonstrate(rng).events) for _ in range(20))


def test_an_empty_truth_is_demonstrated_by_doing_nothing():
    teacher = SimulatedTeacher(get_domain("synthetic"), 0)
    demo = teacher.demonstrate(np.random.default_rng(0))
    assert demo.events == () and len(demo.trace) == 1


@pytest.mark.parametrize("kwargs, message", [
    ({"demo_mode": "lazy"}, "unknown demonstration mode 'lazy'; expected one of required-only, optimal"),
    ({"noise": 1.5}, r"noise must be a probability in \[0, 1\], got 1.5"),
    ({"noise": -0.1}, r"noise must be a probability in \[0, 1\], got -0.1"),
])
def test_bad_teacher_settings_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SimulatedTeacher(get_domain("dinner"), 0, **kwargs)
