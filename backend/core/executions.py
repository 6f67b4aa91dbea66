"""The execution graph of a domain: every distinguishable execution as a node of a DAG.

Every template clause depends only on first occurrences, so an execution is summarised by the
order in which orderable propositions first occurred and the set of the others that occurred.
Nodes are these summaries; an edge makes one more proposition occur. This DAG is the product of
the environment with the clause-status reward machine, with stochastic failures (self-loops)
factored out, and is shared by planning, active queries and satisfiability checks.
Dinner table: 326 nodes (ordered subsets of 5 objects). Synthetic 5+5: 326 x 32 = 10,432.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .domain import Domain

NodeKey = tuple[tuple[str, ...], frozenset[str]]


@dataclass(eq=False)
class ExecutionGraph:
    """Nodes (execution summaries), their satisfied-clause masks and their children."""

    domain: Domain
    keys: list[NodeKey]
    events: list[tuple[str, ...]]
    sat: np.ndarray
    depth: np.ndarray
    child: np.ndarray

    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return len(self.keys)

    @property
    def levels(self) -> list[np.ndarray]:
        """Node indices grouped by depth, shallowest first."""
        return [np.flatnonzero(self.depth == d) for d in range(int(self.depth.max()) + 1)]


@lru_cache(maxsize=None)
def execution_graph(domain: Domain) -> ExecutionGraph:
    """Build (once per domain) the execution DAG by breadth-first search from the empty execution."""
    space = domain.clause_space
    space.check_fits_numpy()
    props = domain.propositions
    orderable = set(domain.orderable)
    root: NodeKey = ((), frozenset())
    keys: list[NodeKey] = [root]
    events: list[tuple[str, ...]] = [()]
    index: dict[NodeKey, int] = {root: 0}
    children: list[list[int]] = []
    i = 0
    while i < len(keys):
        order, others = keys[i]
        row = []
        for p in props:
            if p in order or p in others:
                row.append(-1)
                continue
            key: NodeKey = (order + (p,), others) if p in orderable else (order, others | {p})
            if key not in index:
                index[key] = len(keys)
                keys.append(key)
                events.append(events[i] + (p,))
            row.append(index[key])
        children.append(row)
        i += 1
    sat = np.array(
        [space.sat_mask_of_first({p: t + 1 for t, p in enumerate(ev)}) for ev in events], dtype=np.uint64
    )
    depth = np.array([len(ev) for ev in events], dtype=np.int64)
    child = np.array(children, dtype=np.int64).reshape(len(keys), len(props))
    return ExecutionGraph(domain, keys, events, sat, depth, child)
