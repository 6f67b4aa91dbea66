"""The formula parser's nesting limit: deep and long inputs parse or are refused with a ParseError, never a
RecursionError, whatever Python's stack allows."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tableteach.core.domain import get_domain
from tableteach.core.ltl import MAX_DEPTH, FormulaTooDeepError, ParseError, Prop, parse, to_text

UNARY = ["!", "X ", "WX ", "F ", "G "]
BINARY = [" & ", " | ", " -> ", " U ", " R "]


def _depth(formula) -> int:
    from tableteach.core.ltl import children

    stack, deepest = [(formula, 0)], 0
    while stack:
        node, depth = stack.pop()
        deepest = max(deepest, depth)
        stack.extend((child, depth + 1) for child in children(node))
    return deepest


@st.composite
def nested_texts(draw: st.DrawFn) -> str:
    """Formula text nested by a random mix of prefix operators, parentheses and binary operators, up to
    several times the limit deep (sometimes broken on purpose: an unclosed parenthesis or a stray operator)."""
    levels = draw(st.integers(1, 3 * MAX_DEPTH))
    text = draw(st.sampled_from(["a", "b", "true"]))
    for _ in range(levels):
        kind = draw(st.integers(0, 2))
        if kind == 0:
            text = draw(st.sampled_from(UNARY)) + text
        elif kind == 1:
            text = f"({text})"
        else:
            other = draw(st.sampled_from(["a", "b", "c"]))
            op = draw(st.sampled_from(BINARY))
            text = f"({text}{op}{other})" if draw(st.booleans()) else f"{other}{op}{text}"
    if draw(st.integers(0, 9)) == 0:
        text = draw(st.sampled_from(["(", ")", "& ", "!"])) + text
    return text


@settings(max_examples=150, deadline=None)
@given(nested_texts())
def test_deep_input_parses_within_the_limit_or_is_a_parse_error(text: str) -> None:
    try:
        formula = parse(text)
    except RecursionError as exc:  # pragma: no cover - what the limit is there to prevent
        raise AssertionError("the parser recursed instead of refusing by policy") from exc
    except ParseError as exc:
        assert str(exc).startswith("at position ") and len(str(exc).splitlines()) == 1
        return
    assert _depth(formula) <= MAX_DEPTH
    assert parse(to_text(formula)) == formula  # what the limit lets through works all the way down


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from(["F(bowl)", "G(!fork)", "(!bowl U dinner_plate)", "F(knife)"]), min_size=1,
                max_size=400), st.sampled_from([" & ", " | "]))
def test_long_flat_input_is_one_node_not_a_deep_one(clauses: list[str], op: str) -> None:
    formula = parse(op.join(clauses))
    assert _depth(formula) <= 3
    if op == " & ":  # a long conjunction of template clauses is a task the clause space understands
        space = get_domain("dinner").clause_space
        assert space.text_of(space.mask_of_formula(formula)) == space.text_of(space.mask_of_formula(
            " & ".join(sorted(set(clauses)))))


@pytest.mark.parametrize("text", ["!" * 1990 + "a", "(" * 996 + "a" + ")" * 996, " U ".join(["a"] * 500),
                                  " -> ".join(["a"] * 500), "((" * 300 + "a" + " & b)" * 300 + ")" * 300])
def test_the_issues_deep_formulas_are_refused_by_policy(text: str) -> None:
    with pytest.raises(FormulaTooDeepError) as info:
        parse(text)
    assert f"at most {MAX_DEPTH} nested" in str(info.value) and text not in str(info.value)


def test_nesting_up_to_the_limit_is_accepted() -> None:
    assert _depth(parse("!" * MAX_DEPTH + "a")) == MAX_DEPTH
    assert parse("(" * MAX_DEPTH + "a" + ")" * MAX_DEPTH) == Prop("a")
    with pytest.raises(FormulaTooDeepError):
        parse("!" * (MAX_DEPTH + 1) + "a")
