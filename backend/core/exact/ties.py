"""A uniform draw among every execution tied for the most uncertain query, from the executions the moves keep.

The enumerating learner draws uniformly among tied executions, an execution being a summary: the order in
which objects were first placed and the set of threats visited. The search keeps one execution or a few of
each class of equal scores (``moves.py``): the executions reached by swapping adjacent objects that
commute and by renaming interchangeable objects. A summary's class is fixed by its DAG (every pair of its
objects that do not commute, oriented as they occurred) up to renaming: its members are the DAG's linear
extensions, renamed in every way. So a class is drawn with probability in proportion to its size (each
class counted once however many kept executions it has), then one of its members uniformly.

Which objects commute comes from the weakest data pattern, in one of two ways. With an acceptable
execution among its data, the objects no datum mentions were never placed there, so they may precede
nothing: they commute with each other and depend only on objects every acceptable execution placed.
Without one (the pattern allows everything), no two objects commute and the DAG is the whole order. Either
way a renaming keeps the DAG exactly when it sends each renamed object to one of its group with the same
signature (the other objects before it that it depends on, or its place in the whole order), so a class
holds ext(DAG) * prod over groups N! / (N - k)! / prod over signatures m! summaries, for N members of a
group, k of them used and m used ones sharing a signature.
"""

from __future__ import annotations

import math
from collections import Counter
from functools import lru_cache
from typing import Hashable, Sequence

import numpy as np

from .moves import Moves


def whole_order(moves: Moves) -> bool:
    """True if no two objects commute (the weakest pattern allows every order)."""
    objects = np.flatnonzero(moves.orderable >= 0)
    within = moves.commute[np.ix_(objects, objects)]
    return not within[~np.eye(objects.size, dtype=bool)].any()


def _predecessors(moves: Moves, objects: Sequence[int]) -> tuple[int, ...]:
    """For each object of an execution (by position), the mask of earlier positions it depends on."""
    return tuple(sum(1 << j for j in range(t) if not moves.commute[objects[j], z]) for t, z in enumerate(objects))


@lru_cache(maxsize=4096)
def _completions(pred: tuple[int, ...]) -> tuple[int, ...]:
    """For every set of positions taken so far (a mask), how many orders of the rest keep every dependency."""
    k = len(pred)
    full = (1 << k) - 1
    ways = [0] * (1 << k)
    ways[full] = 1
    for mask in range(full - 1, -1, -1):
        ways[mask] = sum(ways[mask | 1 << v] for v in range(k) if not mask >> v & 1 and pred[v] & ~mask == 0)
    return tuple(ways)


def _signatures(moves: Moves, events: Sequence[int], whole: bool) -> list[tuple[int, Hashable]]:
    """(group, signature) of every renameable proposition of an execution."""
    objects = [z for z in events if moves.orderable[z] >= 0]
    out: list[tuple[int, Hashable]] = []
    for t, z in enumerate(objects):
        if moves.group[z] >= 0:
            before = t if whole else tuple(sorted(int(y) for y in objects[:t] if not moves.commute[y, z]))
            out.append((int(moves.group[z]), before))
    out += [(int(moves.group[z]), None) for z in events if moves.orderable[z] < 0 and moves.group[z] >= 0]
    return out


def class_key(moves: Moves, events: Sequence[int], whole: bool | None = None) -> Hashable:
    """The same for every execution of one class, different for any two classes (whole: ``whole_order``)."""
    whole = whole_order(moves) if whole is None else whole
    objects = [int(z) for z in events if moves.orderable[z] >= 0]
    fixed_threats = frozenset(int(z) for z in events if moves.orderable[z] < 0 and moves.group[z] < 0)
    renamed = tuple(sorted(Counter(_signatures(moves, events, whole)).items(), key=repr))
    if whole:
        return tuple(z if moves.group[z] < 0 else -1 - int(moves.group[z]) for z in objects), fixed_threats, renamed
    fixed = [z for z in objects if moves.group[z] < 0]
    orders = frozenset((a, z) for t, z in enumerate(fixed) for a in fixed[:t] if not moves.commute[a, z])
    return frozenset(fixed), orders, fixed_threats, renamed


def class_size(moves: Moves, events: Sequence[int], whole: bool | None = None) -> int:
    """How many summaries the execution's class holds (whole: ``whole_order``)."""
    whole = whole_order(moves) if whole is None else whole
    objects = [int(z) for z in events if moves.orderable[z] >= 0]
    orders = 1 if whole else _completions(_predecessors(moves, objects))[0]
    signatures = _signatures(moves, events, whole)
    members = Counter(int(g) for g in moves.group if g >= 0)
    used = Counter(g for g, _ in signatures)
    renamings = math.prod(math.perm(members[g], k) for g, k in used.items())
    alike = math.prod(math.factorial(m) for m in Counter(signatures).values())
    return orders * renamings // alike


def draw_member(moves: Moves, events: Sequence[int], rng: np.random.Generator,
                whole: bool | None = None) -> tuple[int, ...]:
    """One execution of the class of these events, uniformly (threats stay where they were)."""
    objects = [int(z) for z in events if moves.orderable[z] >= 0]
    order = objects
    if not (whole_order(moves) if whole is None else whole):
        pred = _predecessors(moves, objects)
        ways = _completions(pred)
        mask, order = 0, []
        while len(order) < len(objects):
            free = [v for v in range(len(objects)) if not mask >> v & 1 and pred[v] & ~mask == 0]
            weights = np.array([ways[mask | 1 << v] for v in free], dtype=float)
            v = free[int(rng.choice(len(free), p=weights / weights.sum()))]
            mask |= 1 << v
            order.append(objects[v])
    rename: dict[int, int] = {}
    for g in sorted({int(g) for g in moves.group if g >= 0}):
        members = [int(i) for i in np.flatnonzero(moves.group == g)]
        rename.update(zip(members, (int(i) for i in rng.permutation(members)), strict=True))
    placed = iter(order)
    slots = [next(placed) if moves.orderable[z] >= 0 else int(z) for z in events]
    return tuple(rename.get(z, z) for z in slots)


def draw_tied(moves: Moves, tied: Sequence[Sequence[int]], rng: np.random.Generator) -> tuple[int, tuple[int, ...]]:
    """Which of the tied kept executions stands for the class drawn (in proportion to its size, each class
    once), and the execution drawn uniformly from that class."""
    whole = whole_order(moves)
    first: dict[Hashable, int] = {}
    for k, events in enumerate(tied):
        first.setdefault(class_key(moves, events, whole), k)
    stands = list(first.values())
    sizes = np.array([class_size(moves, tied[k], whole) for k in stands], dtype=float)
    k = stands[int(rng.choice(len(stands), p=sizes / sizes.sum()))]
    return k, draw_member(moves, tied[k], rng, whole)
