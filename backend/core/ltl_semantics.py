"""Finite-trace LTL semantics: direct evaluation and Bacchus-Kabanza progression.

A trace is a non-empty sequence of states; a state is the set of propositions true in it.
``evaluate`` is the textbook LTLf definition (strong next, strong until). ``progress`` rewrites a
formula through one state (Bacchus & Kabanza 2000); after the last state, ``accepts_at_end``
applies the end-of-trace rule: G/R residuals accept, pending F/U/X obligations reject.
Progression works on negation normal form so that the rule stays exact under negation; the
internal atom END (true only past the last state) keeps strong and weak next apart.
"""

from __future__ import annotations

from typing import AbstractSet, Sequence

from .ltl import (
    FALSE,
    TRUE,
    Always,
    And,
    Const,
    End,
    Eventually,
    Formula,
    Implies,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
    WeakNext,
    conj,
    disj,
)

State = AbstractSet[str]
Trace = Sequence[State]


def _check_trace(trace: Trace) -> None:
    if len(trace) == 0:
        raise ValueError("a trace must have at least one state (the initial state)")


def evaluate(formula: Formula, trace: Trace) -> bool:
    """Whether a non-empty finite trace satisfies the formula at its first state."""
    _check_trace(trace)
    return _truth_vector(formula, trace)[0]


def _truth_vector(formula: Formula, trace: Trace) -> list[bool]:
    """Truth of the formula at every position of the trace (dynamic programming from the end)."""
    n = len(trace)
    if isinstance(formula, Const):
        return [formula.value] * n
    if isinstance(formula, End):
        return [False] * n
    if isinstance(formula, Prop):
        return [formula.name in state for state in trace]
    if isinstance(formula, Not):
        return [not v for v in _truth_vector(formula.arg, trace)]
    if isinstance(formula, And):
        vectors = [_truth_vector(arg, trace) for arg in formula.args]
        return [all(column) for column in zip(*vectors, strict=True)]
    if isinstance(formula, Or):
        vectors = [_truth_vector(arg, trace) for arg in formula.args]
        return [any(column) for column in zip(*vectors, strict=True)]
    if isinstance(formula, Implies):
        left, right = _truth_vector(formula.left, trace), _truth_vector(formula.right, trace)
        return [(not a) or b for a, b in zip(left, right, strict=True)]
    if isinstance(formula, (Next, WeakNext)):
        arg = _truth_vector(formula.arg, trace)
        last = isinstance(formula, WeakNext)
        return [arg[i + 1] if i + 1 < n else last for i in range(n)]
    if isinstance(formula, (Eventually, Always)):
        arg = _truth_vector(formula.arg, trace)
        out = [False] * n
        acc = isinstance(formula, Always)
        for i in range(n - 1, -1, -1):
            acc = (acc and arg[i]) if isinstance(formula, Always) else (acc or arg[i])
            out[i] = acc
        return out
    if isinstance(formula, (Until, Release)):
        left, right = _truth_vector(formula.left, trace), _truth_vector(formula.right, trace)
        out = [False] * n
        if isinstance(formula, Until):
            later = False  # strong: beyond the end nothing holds
            for i in range(n - 1, -1, -1):
                later = right[i] or (left[i] and later)
                out[i] = later
        else:
            later = True  # release: vacuously true beyond the end
            for i in range(n - 1, -1, -1):
                later = right[i] and (left[i] or later)
                out[i] = later
        return out
    raise TypeError(f"not a formula: {formula!r}")


def nnf(formula: Formula, negate: bool = False) -> Formula:
    """Negation normal form (negations only on propositions), with X/WX and U/R as duals."""
    if isinstance(formula, Const):
        return Const(formula.value != negate)
    if isinstance(formula, Prop):
        return Not(formula) if negate else formula
    if isinstance(formula, End):
        return Not(formula) if negate else formula
    if isinstance(formula, Not):
        return nnf(formula.arg, not negate)
    if isinstance(formula, And):
        parts = tuple(nnf(arg, negate) for arg in formula.args)
        return Or(parts) if negate else And(parts)
    if isinstance(formula, Or):
        parts = tuple(nnf(arg, negate) for arg in formula.args)
        return And(parts) if negate else Or(parts)
    if isinstance(formula, Implies):
        return nnf(Or((Not(formula.left), formula.right)), negate)
    if isinstance(formula, Next):
        return WeakNext(nnf(formula.arg, True)) if negate else Next(nnf(formula.arg))
    if isinstance(formula, WeakNext):
        return Next(nnf(formula.arg, True)) if negate else WeakNext(nnf(formula.arg))
    if isinstance(formula, Eventually):
        return Always(nnf(formula.arg, True)) if negate else Eventually(nnf(formula.arg))
    if isinstance(formula, Always):
        return Eventually(nnf(formula.arg, True)) if negate else Always(nnf(formula.arg))
    if isinstance(formula, Until):
        if negate:
            return Release(nnf(formula.left, True), nnf(formula.right, True))
        return Until(nnf(formula.left), nnf(formula.right))
    if isinstance(formula, Release):
        if negate:
            return Until(nnf(formula.left, True), nnf(formula.right, True))
        return Release(nnf(formula.left), nnf(formula.right))
    raise TypeError(f"not a formula: {formula!r}")


def _and(left: Formula, right: Formula) -> Formula:
    if left == FALSE or right == FALSE:
        return FALSE
    if left == TRUE:
        return right
    if right == TRUE or left == right:
        return left
    return conj((left, right))


def _or(left: Formula, right: Formula) -> Formula:
    if left == TRUE or right == TRUE:
        return TRUE
    if left == FALSE:
        return right
    if right == FALSE or left == right:
        return left
    return disj((left, right))


def progress(formula: Formula, state: State) -> Formula:
    """Progress an NNF formula through one state: what the rest of the trace must satisfy."""
    if isinstance(formula, Const):
        return formula
    if isinstance(formula, End):
        return FALSE  # a real state follows, so this is not the end
    if isinstance(formula, Prop):
        return Const(formula.name in state)
    if isinstance(formula, Not):
        if isinstance(formula.arg, End):
            return TRUE  # a state exists
        if not isinstance(formula.arg, Prop):
            raise ValueError("progress expects negation normal form; call nnf() first")
        return Const(formula.arg.name not in state)
    if isinstance(formula, And):
        result: Formula = TRUE
        for arg in formula.args:
            result = _and(result, progress(arg, state))
        return result
    if isinstance(formula, Or):
        result = FALSE
        for arg in formula.args:
            result = _or(result, progress(arg, state))
        return result
    if isinstance(formula, Next):
        return _and(Not(End()), formula.arg)  # strong: a next state must exist
    if isinstance(formula, WeakNext):
        return _or(End(), formula.arg)
    if isinstance(formula, Eventually):
        return _or(progress(formula.arg, state), formula)
    if isinstance(formula, Always):
        return _and(progress(formula.arg, state), formula)
    if isinstance(formula, Until):
        return _or(progress(formula.right, state), _and(progress(formula.left, state), formula))
    if isinstance(formula, Release):
        return _and(progress(formula.right, state), _or(progress(formula.left, state), formula))
    raise ValueError(f"progress expects negation normal form, got {type(formula).__name__}")


def accepts_at_end(residual: Formula) -> bool:
    """End-of-trace rule for a residual after the last state: G/R/END accept; F/U/X, !END and literals reject."""
    if isinstance(residual, Const):
        return residual.value
    if isinstance(residual, (End, Always, Release)):
        return True
    if isinstance(residual, (Prop, Not, Next, Eventually, Until)):
        return False
    if isinstance(residual, WeakNext):
        return True
    if isinstance(residual, And):
        return all(accepts_at_end(arg) for arg in residual.args)
    if isinstance(residual, Or):
        return any(accepts_at_end(arg) for arg in residual.args)
    raise ValueError(f"not a residual in negation normal form: {residual!r}")


def progress_trace(formula: Formula, trace: Trace) -> Formula:
    """The residual of a formula after progressing it through every state of a trace."""
    residual = nnf(formula)
    for state in trace:
        residual = progress(residual, state)
    return residual


def accepts(formula: Formula, trace: Trace) -> bool:
    """Whether a trace satisfies a formula, decided by progression and the end-of-trace rule."""
    _check_trace(trace)
    return accepts_at_end(progress_trace(formula, trace))
