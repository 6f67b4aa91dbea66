"""LTL syntax and semantics: round trips, errors, progression against direct evaluation."""

import pytest
from hypothesis import given

from tableteach.core.ltl import (
    Always, And, Eventually, Not, ParseError, Prop, UnknownPropositionError, Until, parse, to_text,
)
from tableteach.core.ltl_semantics import accepts, evaluate, nnf, progress_trace

from .strategies import formulas, traces


def test_parse_template_example():
    f = parse("F(bowl) & (!bowl U dinner_plate) & G(!small_plate)")
    assert f == And((
        Eventually(Prop("bowl")),
        Until(Not(Prop("bowl")), Prop("dinner_plate")),
        Always(Not(Prop("small_plate"))),
    ))
    assert to_text(f) == "F(bowl) & (!bowl U dinner_plate) & G(!small_plate)"


def test_precedence_and_associativity():
    assert parse("a -> b -> c") == parse("a -> (b -> c)")
    assert parse("a | b & c") == parse("a | (b & c)")
    assert parse("!a U b") == Until(Not(Prop("a")), Prop("b"))
    assert parse("a U b U c") == parse("a U (b U c)")
    assert parse("X X a") == parse("X(X(a))")


@given(formulas())
def test_print_parse_round_trip(f):
    assert parse(to_text(f)) == f


@pytest.mark.parametrize(
    "text, position, expected",
    [
        ("F(bowl", 6, "')'"),
        ("a & ", 4, "a proposition"),
        ("a b", 2, "an operator"),
        ("a $ b", 2, "an operator, proposition or parenthesis"),
        ("", 0, "a formula"),
        ("G()", 2, "a proposition"),
    ],
)
def test_parse_errors_name_position_and_expectation(text, position, expected):
    with pytest.raises(ParseError) as info:
        parse(text)
    assert info.value.position == position
    assert expected in str(info.value)


def test_unknown_propositions_are_named():
    with pytest.raises(UnknownPropositionError) as info:
        parse("F(spoon) & F(bowl) & G(!cup)", propositions=["bowl", "fork"])
    assert info.value.unknown == ["cup", "spoon"]
    assert "cup, spoon" in str(info.value)


@given(formulas(), traces())
def test_progression_agrees_with_direct_evaluation(f, trace):
    assert accepts(f, trace) == evaluate(f, trace)


@given(formulas(), traces())
def test_nnf_preserves_meaning(f, trace):
    assert evaluate(nnf(f), trace) == evaluate(f, trace)


def test_end_of_trace_rule_on_template_clauses():
    trace = [frozenset(), frozenset({"a"})]
    assert progress_trace(parse("G(!b)"), trace) == parse("G(!b)")  # safety residual accepts
    assert accepts(parse("G(!b)"), trace)
    assert not accepts(parse("F(b)"), trace)  # pending F rejects
    assert not accepts(parse("!a U b"), [frozenset()])  # pending U rejects
    assert accepts(parse("!b U a"), trace)


def test_strong_and_weak_next_at_the_end():
    last = [frozenset({"a"})]
    assert not evaluate(parse("X a"), last) and not accepts(parse("X a"), last)
    assert evaluate(parse("!X a"), last) and accepts(parse("!X a"), last)
    assert evaluate(parse("WX a"), last) and accepts(parse("WX a"), last)


def test_empty_trace_is_rejected():
    with pytest.raises(ValueError, match="at least one state"):
        evaluate(parse("a"), [])
