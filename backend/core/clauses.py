"""The template clause universe of a task and clause sets as bitmasks.

Clauses are ``G(!p)`` for every forbiddable p, ``F(p)`` for every orderable p and ``(!b U a)``
("a before b") for every ordered pair of distinct orderable propositions. Bit layout: G clauses
first, then F clauses (together the *unary* bits), then order clauses. A hypothesis (candidate
task formula) is a conjunction of clauses, i.e. a bitmask; its Nconj counts every clause in it.
Every clause's truth depends only on the first occurrence of each proposition, which is what
makes exact enumeration and planning cheap.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Mapping, Sequence

import numpy as np

from .ltl import Always, And, Const, Eventually, Formula, Not, Prop, Until, conj, parse, to_text
from .ltl_semantics import Trace

MAX_CLAUSES = 63  # what a 64-bit numpy mask holds: the enumerated spaces' limit (core.hypotheses), not a ClauseSpace's


@dataclass(frozen=True)
class Clause:
    """One template clause: kind 'G' (never p), 'F' (eventually p) or 'U' (first before second)."""

    kind: str
    first: str
    second: str | None = None

    def formula(self) -> Formula:
        """This clause as an LTL formula."""
        if self.kind == "G":
            return Always(Not(Prop(self.first)))
        if self.kind == "F":
            return Eventually(Prop(self.first))
        return Until(Not(Prop(self.second)), Prop(self.first))  # type: ignore[arg-type]

    def text(self) -> str:
        """The clause's canonical text: G(!p), F(p) or (!b U a)."""
        return to_text(self.formula())


def humanize(name: str) -> str:
    """An object or proposition name as people read it: dinner_plate -> dinner plate."""
    return name.replace("_", " ")


@dataclass(frozen=True)
class ClauseSpace:
    """All template clauses over a task's propositions, with their bit positions."""

    orderable: tuple[str, ...]
    forbiddable: tuple[str, ...]
    verb: str = "place"
    clauses: tuple[Clause, ...] = field(init=False)

    def __post_init__(self) -> None:
        clauses = [Clause("G", p) for p in self.forbiddable]
        clauses += [Clause("F", p) for p in self.orderable]
        clauses += [Clause("U", a, b) for a in self.orderable for b in self.orderable if a != b]
        object.__setattr__(self, "clauses", tuple(clauses))

    @property
    def n_clauses(self) -> int:
        """Number of clauses in the universe."""
        return len(self.clauses)

    def check_fits_numpy(self) -> None:
        """ValueError unless every mask of this space fits a 64-bit numpy integer (the enumerated learner's arrays;
        masks as Python integers, as used here, have no limit)."""
        if self.n_clauses > MAX_CLAUSES:
            raise ValueError(
                f"{self.n_clauses} clauses do not fit a 64-bit mask; expected at most {MAX_CLAUSES} "
                f"(fewer orderable propositions)"
            )

    @property
    def n_unary(self) -> int:
        """Number of G and F clauses (the low bits)."""
        return len(self.forbiddable) + len(self.orderable)

    @property
    def propositions(self) -> tuple[str, ...]:
        """Every proposition that some clause mentions, orderable ones first."""
        return self.orderable + tuple(p for p in self.forbiddable if p not in self.orderable)

    @cached_property
    def index(self) -> Mapping[Clause, int]:
        """Bit position of each clause."""
        return {clause: i for i, clause in enumerate(self.clauses)}

    def bit(self, clause: Clause) -> int:
        """The single-bit mask of a clause."""
        return 1 << self.index[clause]

    def g_bit(self, p: str) -> int:
        """Mask of G(!p)."""
        return self.bit(Clause("G", p))

    def f_bit(self, p: str) -> int:
        """Mask of F(p)."""
        return self.bit(Clause("F", p))

    def before_bit(self, a: str, b: str) -> int:
        """Mask of (!b U a): a before b."""
        return self.bit(Clause("U", a, b))

    @property
    def unary_mask(self) -> int:
        """Mask of all G and F clauses."""
        return (1 << self.n_unary) - 1

    @property
    def full_mask(self) -> int:
        """Mask of every clause."""
        return (1 << self.n_clauses) - 1

    # ------------------------------------------------------------ masks <-> clauses

    def clauses_of(self, mask: int) -> list[Clause]:
        """The clauses in a mask, in bit order."""
        return [c for i, c in enumerate(self.clauses) if mask >> i & 1]

    def formula_of(self, mask: int) -> Formula:
        """The conjunction of a mask's clauses (true for the empty mask)."""
        return conj(c.formula() for c in self.clauses_of(mask))

    def text_of(self, mask: int) -> str:
        """Canonical text of a mask's formula."""
        return to_text(self.formula_of(mask))

    def clause_texts(self, mask: int) -> list[str]:
        """Canonical text of each clause in a mask."""
        return [c.text() for c in self.clauses_of(mask)]

    def mask_of_formula(self, formula: Formula | str) -> int:
        """Mask of a conjunction of template clauses; anything else is a ValueError naming it."""
        if isinstance(formula, str):
            formula = parse(formula, self.propositions)
        if formula == Const(True):
            return 0
        parts = formula.args if isinstance(formula, And) else (formula,)
        mask = 0
        for part in parts:
            if isinstance(part, And):
                mask |= self.mask_of_formula(part)
                continue
            clause = self._clause_from_formula(part)
            mask |= self.bit(clause)
        return mask

    @cached_property
    def _clause_by_formula(self) -> dict[Formula, Clause]:
        return {c.formula(): c for c in reversed(self.clauses)}  # reversed: the first clause wins, as before

    def _clause_from_formula(self, part: Formula) -> Clause:
        expected = "a clause G(!p), F(p) or (!b U a) over this task's propositions"
        clause = self._clause_by_formula.get(part)
        if clause is None:
            raise ValueError(f"{to_text(part)!r} is not a template clause of this task; expected {expected}")
        return clause

    # ------------------------------------------------------------ semantics

    def sat_mask(self, trace: Trace) -> int:
        """Mask of the clauses that a whole finite trace satisfies (fast path, first occurrences)."""
        if len(trace) == 0:
            raise ValueError("a trace must have at least one state (the initial state)")
        first: dict[str, int] = {}
        for t, state in enumerate(trace):
            for p in state:
                first.setdefault(p, t)
        return self.sat_mask_of_first(first)

    def sat_mask_of_first(self, first: Mapping[str, int]) -> int:
        """Satisfied-clause mask given each proposition's first-occurrence time (absent: never)."""
        mask = 0
        for i, clause in enumerate(self.clauses):
            if clause.kind == "G":
                ok = clause.first not in first
            elif clause.kind == "F":
                ok = clause.first in first
            else:
                a, b = first.get(clause.first), first.get(clause.second)  # type: ignore[arg-type]
                ok = a is not None and (b is None or a <= b)
            if ok:
                mask |= 1 << i
        return mask

    def expanded_mask(self, mask: int, metric: str = "authors") -> int:
        """Token set of a formula for the similarity metric, as a mask (see metrics.SIMILARITY_METRICS).

        "authors": an order (a before b) also gives F(a); the order itself is dropped when the
        formula has G(!b). "strict": the order and its F(a) are dropped when a or b is forbidden.
        """
        if metric not in ("authors", "strict"):
            raise ValueError(f"unknown similarity metric {metric!r}; expected authors or strict")
        forbidden = {c.first for c in self.clauses_of(mask) if c.kind == "G"}
        out = 0
        for clause in self.clauses_of(mask):
            if clause.kind == "U":
                if metric == "authors":
                    out |= self.f_bit(clause.first)
                    if clause.second in forbidden:
                        continue
                else:
                    if clause.first in forbidden or clause.second in forbidden:
                        continue
                    out |= self.f_bit(clause.first)
            out |= self.bit(clause)
        return out

    # ------------------------------------------------------------ plain English

    def describe(self, mask: int) -> str:
        """A plain-English description, e.g. 'place the dinner plate before the bowl; never place the fork'."""
        return describe_clauses(self.clauses_of(mask), self.verb)


def describe_clauses(clauses: Sequence[Clause], verb: str = "place") -> str:
    """Plain English for a list of template clauses (``ClauseSpace.describe`` without a mask)."""
    if not clauses:
        return "anything is acceptable"
    phrases: list[str] = []
    orders = [c for c in clauses if c.kind == "U"]
    required = [c.first for c in clauses if c.kind == "F"]
    forbidden = [c.first for c in clauses if c.kind == "G"]
    if required:
        phrases.append(f"{verb} " + join_words([f"the {humanize(p)}" for p in required]))
    for c in orders:
        phrases.append(f"{verb} the {humanize(c.first)} before the {humanize(c.second or '')}")
    if forbidden:
        phrases.append(f"never {verb} " + join_words([f"the {humanize(p)}" for p in forbidden]))
    return "; ".join(phrases)


def join_words(items: Sequence[str]) -> str:
    """'a', 'a and b', 'a, b and c'."""
    if len(items) <= 1:
        return "".join(items)
    return ", ".join(items[:-1]) + " and " + items[-1]


def popcount(masks: np.ndarray) -> np.ndarray:
    """Number of set bits in each element of an unsigned integer array."""
    return np.bitwise_count(masks).astype(np.int64)

