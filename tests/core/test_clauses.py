"""Clause space: layout, fast-path semantics against general LTL, conversions, English."""

import pytest
from hypothesis import given, strategies as st

from tableteach.core.domain import get_domain
from tableteach.core.ltl_semantics import evaluate

from .strategies import traces

DINNER = get_domain("dinner")
SPACE = DINNER.clause_space


def test_dinner_and_synthetic_have_30_clauses():
    assert SPACE.n_clauses == 30 and SPACE.n_unary == 10
    synth = get_domain("synthetic").clause_space
    assert synth.n_clauses == 30
    assert [c.text() for c in synth.clauses[:5]] == [f"G(!t{i})" for i in range(5)]


@given(traces(props=("dinner_plate", "small_plate", "bowl", "knife", "fork"), max_len=7))
def test_sat_mask_agrees_with_general_ltl(trace):
    mask = SPACE.sat_mask(trace)
    for i, clause in enumerate(SPACE.clauses):
        assert bool(mask >> i & 1) == evaluate(clause.formula(), trace), clause.text()


@given(st.integers(min_value=0, max_value=(1 << 30) - 1))
def test_mask_formula_round_trip(mask):
    text = SPACE.text_of(mask)
    assert SPACE.mask_of_formula(text) == mask


def test_clause_texts_follow_the_contract():
    mask = SPACE.before_bit("dinner_plate", "bowl") | SPACE.g_bit("small_plate") | SPACE.f_bit("bowl")
    assert SPACE.clause_texts(mask) == ["G(!small_plate)", "F(bowl)", "(!bowl U dinner_plate)"]


def test_plain_english():
    mask = SPACE.mask_of_formula("(!bowl U dinner_plate) & G(!small_plate)")
    assert SPACE.describe(mask) == "place the dinner plate before the bowl; never place the small plate"
    assert SPACE.describe(0) == "anything is acceptable"


def test_non_template_formula_is_refused_with_its_text():
    with pytest.raises(ValueError, match="not a template clause"):
        SPACE.mask_of_formula("F(bowl) & X(fork)")


def test_expanded_mask_authors_drop_an_order_only_when_its_later_item_is_forbidden():
    mask = SPACE.mask_of_formula("(!bowl U dinner_plate) & (!fork U knife) & (!knife U fork) & G(!fork)")
    expanded = SPACE.expanded_mask(mask)  # the authors' tokens: (a, b) and 'a'; (a, b) gone if G(!b)
    assert SPACE.clause_texts(expanded) == [
        "G(!fork)", "F(dinner_plate)", "F(knife)", "F(fork)", "(!bowl U dinner_plate)", "(!knife U fork)"
    ]


def test_expanded_mask_strict_drops_orders_on_any_forbidden_item_with_their_eventually():
    mask = SPACE.mask_of_formula("(!bowl U dinner_plate) & (!fork U knife) & (!knife U fork) & G(!fork)")
    expanded = SPACE.expanded_mask(mask, "strict")
    assert SPACE.clause_texts(expanded) == ["G(!fork)", "F(dinner_plate)", "(!bowl U dinner_plate)"]
    with pytest.raises(ValueError, match="unknown similarity metric 'iou'"):
        SPACE.expanded_mask(mask, "iou")
