"""Many clause-set constraints as numpy arrays, so that executions and their meets are built without a Python loop.

Row c of a batch is the constraint ``Constraint(g_ok[c], f_ok[c], tuple(into[c]), g_extra[c])``.
Executions are given as first-occurrence ranks of the orderable objects (``ABSENT`` when never
placed) and a bitmask of the extra propositions they made true.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .constraints import Constraint, Vocabulary

ABSENT = np.iinfo(np.int64).max


@dataclass(frozen=True)
class Batch:
    """Constraints as arrays: g_ok, f_ok, g_extra of shape (M,), into of shape (M, n)."""

    g_ok: np.ndarray
    f_ok: np.ndarray
    into: np.ndarray
    g_extra: np.ndarray

    def __len__(self) -> int:
        return int(self.g_ok.shape[0])

    @staticmethod
    def of(constraints: Sequence[Constraint], n: int) -> "Batch":
        """The batch of these constraints over n orderable objects."""
        if not constraints:
            empty = np.zeros(0, dtype=np.int64)
            return Batch(empty, empty, np.zeros((0, n), dtype=np.int64), empty)
        return Batch(np.array([c.g_ok for c in constraints], dtype=np.int64),
                     np.array([c.f_ok for c in constraints], dtype=np.int64),
                     np.array([c.into for c in constraints], dtype=np.int64).reshape(len(constraints), n),
                     np.array([c.g_extra for c in constraints], dtype=np.int64))

    def row(self, c: int) -> Constraint:
        """Row c as a Constraint."""
        return Constraint(int(self.g_ok[c]), int(self.f_ok[c]), tuple(int(v) for v in self.into[c]),
                          int(self.g_extra[c]))

    def take(self, index: np.ndarray) -> "Batch":
        """The rows at these indices."""
        return Batch(self.g_ok[index], self.f_ok[index], self.into[index], self.g_extra[index])

    def meet(self, other: "Batch") -> "Batch":
        """Row-wise intersection (shapes broadcast: one row meets every row)."""
        return Batch(self.g_ok & other.g_ok, self.f_ok & other.f_ok, self.into & other.into,
                     self.g_extra & other.g_extra)

    def reduce(self) -> "Batch":
        """The meet of all rows, as one row."""
        return Batch(*(np.bitwise_and.reduce(getattr(self, f), axis=0, keepdims=True)
                       for f in ("g_ok", "f_ok", "into", "g_extra")))

    def outer_meet(self, other: "Batch") -> "Batch":
        """Every row of self met with every row of other, self's rows outermost (len(self) * len(other) rows)."""
        def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            out = a[:, None] & b[None, :]
            return out.reshape(-1, *a.shape[1:])
        return Batch(cross(self.g_ok, other.g_ok), cross(self.f_ok, other.f_ok), cross(self.into, other.into),
                     cross(self.g_extra, other.g_extra))

    @staticmethod
    def concat(parts: Sequence["Batch"]) -> "Batch":
        """The rows of several batches, in order."""
        return Batch(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("g_ok", "f_ok", "into", "g_extra")))


def rank_of(voc: Vocabulary, events: Sequence[str]) -> tuple[np.ndarray, int]:
    """First-occurrence ranks of the orderable objects (ABSENT if never), and the extras made true, as a mask."""
    ranks = np.full(voc.n, ABSENT, dtype=np.int64)
    index = {p: i for i, p in enumerate(voc.orderable)}
    extra = {p: j for j, p in enumerate(voc.extra)}
    visited = 0
    for t, p in enumerate(events):
        if p in index and ranks[index[p]] == ABSENT:
            ranks[index[p]] = t
        elif p in extra:
            visited |= 1 << extra[p]
    return ranks, visited


def satisfied(voc: Vocabulary, ranks: np.ndarray, visited: np.ndarray) -> Batch:
    """The clauses each execution satisfies (``Vocabulary.satisfied_by`` for a batch of rank rows)."""
    n = voc.n
    bits = np.int64(1) << np.arange(n, dtype=np.int64)
    present = ranks != ABSENT  # (M, n)
    f_ok = (present * bits).sum(axis=1)
    g_ok = ((~present) * bits).sum(axis=1) & voc.forbiddable_orderable
    # a may precede z: a present and (z absent or a first)
    before = present[:, :, None] & (ranks[:, :, None] < ranks[:, None, :])  # (M, a, z); absent z has rank max
    before &= ~np.eye(n, dtype=bool)[None]
    into = (before * bits[None, :, None]).sum(axis=1)
    g_extra = ~np.asarray(visited, dtype=np.int64) & ((1 << len(voc.extra)) - 1)
    return Batch(g_ok.astype(np.int64), f_ok.astype(np.int64), into.astype(np.int64), g_extra.astype(np.int64))


def of_events(voc: Vocabulary, executions: Sequence[Sequence[str]]) -> Batch:
    """The clauses each execution satisfies (``Vocabulary.of_events`` for many executions)."""
    if not executions:
        return Batch.of([], voc.n)
    pairs = [rank_of(voc, e) for e in executions]
    ranks = np.stack([r for r, _ in pairs])
    visited = np.array([v for _, v in pairs], dtype=np.int64)
    return satisfied(voc, ranks, visited)
