"""Which propositions may extend an execution prefix, so that a search visits one execution of each set of equal scores.

Two executions that differ by swapping adjacent propositions x and y have the same P(acceptable)
under a posterior when no datum pattern of it lets x come before y or y before x: the clause sets
differ only in those two orders, which every formula of the posterior's support avoids. Threats
(forbiddable-only propositions) never take part in an order, so they commute with everything.
Among such executions the search keeps those where every adjacent commuting pair is in
proposition order (the lexicographically least of each class has this property). Objects that no
datum mentions are interchangeable (swapping them maps every datum and the prior to themselves),
so of those only the lowest unused one may come next; the least execution of a class keeps both
rules. Both are exact: every execution has one with the same score among those kept.

The clause sets of the children (satisfied clauses, and those not yet violated: the search's upper
bound) are built from the parent's with numpy, for many children at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .batch import Batch
from .posterior import ExactPosterior


@dataclass(frozen=True)
class Moves:
    """Per proposition: its orderable index (or -1), extra index (or -1), which it commutes with, the member
    of its interchangeable group just below it (or -1), and its group (or -1 when a datum mentions it)."""

    names: tuple[str, ...]
    orderable: np.ndarray
    extra: np.ndarray
    commute: np.ndarray
    below: np.ndarray
    group: np.ndarray

    @staticmethod
    def of(posterior: ExactPosterior, propositions: Sequence[str]) -> "Moves":
        """The moves for a posterior: commutation from its weakest data pattern, groups from the data's propositions."""
        voc = posterior.prior.vocabulary
        names = tuple(propositions)
        unknown = [p for p in names if p not in voc.orderable and p not in voc.extra]
        if unknown:
            raise ValueError(f"propositions {', '.join(unknown)} are neither orderable nor forbiddable in this task; "
                             f"expected some of {', '.join(voc.orderable + voc.extra)}")
        orderable = np.array([voc.orderable.index(p) if p in voc.orderable else -1 for p in names])
        extra = np.array([voc.extra.index(p) if p in voc.extra else -1 for p in names])
        weakest = posterior._pattern_batch().into[0]  # every pattern's orders lie within the first one's
        P = len(names)
        commute = np.ones((P, P), dtype=bool)
        for i in range(P):
            for j in range(P):
                a, z = orderable[i], orderable[j]
                if i == j or a >= 0 and z >= 0 and (weakest[z] >> a & 1 or weakest[a] >> z & 1):
                    commute[i, j] = False
        mentioned = set()
        for d in posterior.data:
            s = d.satisfied
            mentioned |= {voc.orderable[i] for i in range(voc.n) if s.f_ok >> i & 1}
            mentioned |= {p for j, p in enumerate(voc.extra) if not s.g_extra >> j & 1}
        forbiddable = set(voc.forbiddable)
        below, group = np.full(P, -1), np.full(P, -1)
        last_of: dict[tuple[bool, bool], int] = {}
        for i, p in enumerate(names):
            if p in mentioned:
                continue
            key = (bool(extra[i] >= 0), p in forbiddable)
            below[i] = last_of.get(key, -1)
            last_of[key] = i
            group[i] = list(last_of).index(key)
        return Moves(names, orderable, extra, commute, below, group)

    def children(self, events: tuple[int, ...], used: int) -> list[int]:
        """Propositions that may come next after these (indices into the propositions)."""
        last = events[-1] if events else -1
        out = []
        for z in range(len(self.names)):
            if used >> z & 1 or self.below[z] >= 0 and not used >> int(self.below[z]) & 1:
                continue
            if last >= 0 and z < last and self.commute[last, z]:
                continue
            out.append(z)
        return out

    def extend(self, exact: Batch, upper: Batch, props: np.ndarray) -> tuple[Batch, Batch]:
        """The children's satisfied clauses and not-yet-violated clauses, row c extended by proposition props[c]."""
        n = exact.into.shape[1]
        o = self.orderable[props]
        e = self.extra[props]
        bit = np.where(o >= 0, np.int64(1) << np.maximum(o, 0), 0).astype(np.int64)
        ebit = np.where(e >= 0, np.int64(1) << np.maximum(e, 0), 0).astype(np.int64)
        f_ok = exact.f_ok | bit
        absent = ((f_ok[:, None] >> np.arange(n, dtype=np.int64)) & 1) == 0
        into = exact.into | np.where(absent, bit[:, None], 0)
        child = Batch(exact.g_ok & ~bit, f_ok, into, exact.g_extra & ~ebit)
        u_into = upper.into.copy()
        rows = np.flatnonzero(o >= 0)
        u_into[rows, o[rows]] = exact.f_ok[rows]  # it occurred now: only what occurred before may precede it
        bound = Batch(upper.g_ok & ~bit, upper.f_ok, u_into, upper.g_extra & ~ebit)
        return child, bound


def lower(exact: Batch) -> Batch:
    """Clauses every extension satisfies: the occurred F items and the orders whose antecedent occurred first."""
    zero = np.zeros_like(exact.g_ok)
    return Batch(zero, exact.f_ok, exact.into, zero)
