"""Clause-set constraints: which template clauses a formula may contain, as per-object bitmasks.

A constraint over n orderable and m extra forbiddable propositions allows, for orderable object i,
``G(!i)`` if ``g_ok`` has bit i, ``F(i)`` if ``f_ok`` has bit i, and ``(!z U a)`` ("a before z")
if ``into[z]`` has bit a; ``g_extra`` does the same for the forbiddable-only propositions.
"Every clause of h lies in C" for the clauses an execution satisfies is "h accepts the execution".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence


@dataclass(frozen=True)
class Constraint:
    """Allowed clauses, as bitmasks over orderable indices (and over extra forbiddables)."""

    g_ok: int
    f_ok: int
    into: tuple[int, ...]
    g_extra: int

    def meet(self, other: "Constraint") -> "Constraint":
        """Clauses allowed by both."""
        return Constraint(
            self.g_ok & other.g_ok,
            self.f_ok & other.f_ok,
            tuple(a & b for a, b in zip(self.into, other.into, strict=True)),
            self.g_extra & other.g_extra,
        )


@dataclass(frozen=True)
class Vocabulary:
    """The propositions of a task: orderable ones (indices 0..n-1) and forbiddable ones."""

    orderable: tuple[str, ...]
    forbiddable: tuple[str, ...]

    @property
    def n(self) -> int:
        """Number of orderable propositions."""
        return len(self.orderable)

    @property
    def extra(self) -> tuple[str, ...]:
        """Forbiddable propositions that are not orderable (synthetic threats)."""
        return tuple(p for p in self.forbiddable if p not in self.orderable)

    @property
    def forbiddable_orderable(self) -> int:
        """Bitmask of orderable indices that may also be forbidden."""
        return sum(1 << i for i, p in enumerate(self.orderable) if p in self.forbiddable)

    def everything(self) -> Constraint:
        """The constraint that allows every clause."""
        full = (1 << self.n) - 1
        into = tuple(full & ~(1 << z) for z in range(self.n))
        return Constraint(self.forbiddable_orderable, full, into, (1 << len(self.extra)) - 1)

    def without(self, kind: str, first: str, second: str | None = None) -> Constraint:
        """Every clause but one: kind 'G', 'F' or 'U' ((!second U first), first before second)."""
        c = self.everything()
        if kind == "G" and first in self.extra:
            return Constraint(c.g_ok, c.f_ok, c.into, c.g_extra & ~(1 << self.extra.index(first)))
        i = self.orderable.index(first)
        if kind == "G":
            return Constraint(c.g_ok & ~(1 << i), c.f_ok, c.into, c.g_extra)
        if kind == "F":
            return Constraint(c.g_ok, c.f_ok & ~(1 << i), c.into, c.g_extra)
        z = self.orderable.index(second)
        into = tuple(m & ~(1 << i) if j == z else m for j, m in enumerate(c.into))
        return Constraint(c.g_ok, c.f_ok, into, c.g_extra)

    def satisfied_by(self, first: Mapping[str, int]) -> Constraint:
        """The clauses an execution satisfies, given each proposition's first-occurrence time."""
        n = self.n
        present = [p in first for p in self.orderable]
        g_ok = sum(1 << i for i in range(n) if not present[i]) & self.forbiddable_orderable
        f_ok = sum(1 << i for i in range(n) if present[i])
        into = []
        for z, pz in enumerate(self.orderable):
            allowed = 0
            for a, pa in enumerate(self.orderable):
                if a != z and present[a] and (not present[z] or first[pa] <= first[pz]):
                    allowed |= 1 << a
            into.append(allowed)
        g_extra = sum(1 << j for j, p in enumerate(self.extra) if p not in first)
        return Constraint(g_ok, f_ok, tuple(into), g_extra)

    def of_trace(self, trace: Sequence[frozenset[str] | Sequence[str]]) -> Constraint:
        """The clauses a whole trace satisfies."""
        return self.satisfied_by(first_occurrences(trace))

    def of_events(self, events: Sequence[str]) -> Constraint:
        """The clauses satisfied by the execution that made these propositions true, in order."""
        return self.satisfied_by({p: t + 1 for t, p in reversed(list(enumerate(events)))})


def first_occurrences(trace: Sequence[frozenset[str] | Sequence[str]]) -> dict[str, int]:
    """Each proposition's first time step in a trace."""
    first: dict[str, int] = {}
    for t, state in enumerate(trace):
        for p in state:
            first.setdefault(p, t)
    return first
