"""Hypothesis strategies for formulas, traces and small domains."""

from hypothesis import strategies as st

from tableteach.core.domain import Domain
from tableteach.core.ltl import (
    Always, And, Const, Eventually, Implies, Next, Not, Or, Prop, Release, Until, WeakNext,
)

PROPS = ("a", "b", "c")


def formulas(props=PROPS, max_leaves: int = 12):
    """Random LTL formulas over the given propositions (every operator of the syntax)."""
    leaves = st.one_of(st.sampled_from([Prop(p) for p in props]), st.sampled_from([Const(True), Const(False)]))

    def extend(children):
        return st.one_of(
            st.builds(Not, children),
            st.builds(Next, children),
            st.builds(WeakNext, children),
            st.builds(Eventually, children),
            st.builds(Always, children),
            st.builds(Until, children, children),
            st.builds(Release, children, children),
            st.builds(Implies, children, children),
            st.builds(lambda xs: And(tuple(xs)), st.lists(children, min_size=2, max_size=3)),
            st.builds(lambda xs: Or(tuple(xs)), st.lists(children, min_size=2, max_size=3)),
        )

    return st.recursive(leaves, extend, max_leaves=max_leaves)


def traces(props=PROPS, max_len: int = 6):
    """Random non-empty traces: lists of sets of propositions."""
    return st.lists(st.frozensets(st.sampled_from(props)), min_size=1, max_size=max_len)


def small_domain(persistent: bool = True) -> Domain:
    """A three-object dinner-like domain (small enough for brute force)."""
    props = ("a", "b", "c")
    return Domain("small", props, props, props, persistent, 1.0, "place")
