"""Priors over task formulas, enumerated exactly (Bayesian specification inference).

Each prior is a generative process over order structures (which ``(!b U a)`` clauses hold)
times independent inclusion of ``F(p)`` and ``G(!p)`` clauses. We enumerate every sampling path
of the order structure and sum the probabilities of paths that yield the same clause set, so the
support is canonical clause sets with exact probabilities.

- chains: a uniform random permutation of the orderable propositions is cut into blocks (a new
  block after each element with probability ``p_new_block``); each block is a linear chain and
  contributes all its ordered pairs. This is the authors' default ("sets of linear chains").
- total-order: one chain over all orderable propositions (chains with ``p_new_block = 0``).
- forest: sub-tasks form a forest. Elements arrive in uniformly random order; each becomes a new
  root with probability ``p_root`` (the first always does), else a child of a uniformly chosen
  earlier element; every element must come before all of its ancestors.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import permutations, product

PairSet = frozenset[tuple[int, int]]

STRUCTURES = ("chains", "total-order", "forest")


@dataclass(frozen=True)
class PriorSpec:
    """Settings of a prior; the named priors are instances of this."""

    structure: str = "chains"
    p_new_block: float = 0.7
    p_root: float = 0.5
    p_eventually: float = 0.5
    p_forbid: float = 0.5
    require_satisfiable: bool = False
    log2_epsilon: float | None = None

    def __post_init__(self) -> None:
        if self.structure not in STRUCTURES:
            raise ValueError(f"unknown prior structure {self.structure!r}; expected one of {', '.join(STRUCTURES)}")
        for name in ("p_new_block", "p_root", "p_eventually", "p_forbid"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {value}")


NAMED_PRIORS: dict[str, PriorSpec] = {
    "chains-2019": PriorSpec("chains", p_forbid=0.0),
    "chains-2020": PriorSpec("chains", p_forbid=0.5),
    "chains-2020-sat": PriorSpec("chains", p_forbid=0.5, require_satisfiable=True),
    "total-order": PriorSpec("total-order", p_forbid=0.5, require_satisfiable=True),
    "forest": PriorSpec("forest", p_forbid=0.5, require_satisfiable=True),
}
DEFAULT_PRIOR = "chains-2020-sat"


def get_prior(name: str) -> PriorSpec:
    """A named prior's settings."""
    if name not in NAMED_PRIORS:
        raise ValueError(f"unknown prior {name!r}; expected one of {', '.join(NAMED_PRIORS)}")
    return NAMED_PRIORS[name]


def order_structures(spec: PriorSpec, n: int) -> dict[PairSet, float]:
    """Exact distribution over sets of (earlier, later) index pairs for n orderable propositions."""
    if spec.structure == "forest":
        return _forest_structures(n, spec.p_root)
    p_new = 0.0 if spec.structure == "total-order" else spec.p_new_block
    return _chain_structures(n, p_new)


def _chain_structures(n: int, p_new: float) -> dict[PairSet, float]:
    out: dict[PairSet, float] = {}
    p_perm = 1.0 / math.factorial(n)
    for perm in permutations(range(n)):
        for cuts in product((False, True), repeat=max(n - 1, 0)):
            p = p_perm * math.prod(p_new if c else 1.0 - p_new for c in cuts)
            if p == 0.0:
                continue
            pairs: set[tuple[int, int]] = set()
            block: list[int] = [perm[0]] if n else []
            for element, cut in zip(perm[1:], cuts, strict=True):
                if cut:
                    block = []
                pairs.update((earlier, element) for earlier in block)
                block.append(element)
            key = frozenset(pairs)
            out[key] = out.get(key, 0.0) + p
    return out


def _forest_structures(n: int, p_root: float) -> dict[PairSet, float]:
    out: dict[PairSet, float] = {}
    p_perm = 1.0 / math.factorial(n)
    # choice[i] = -1 (root) or the position j < i of the parent in the permutation
    choices = [[-1]] + [[-1] + list(range(i)) for i in range(1, n)]
    for perm in permutations(range(n)):
        for choice in product(*choices):
            p = p_perm
            for i, c in enumerate(choice):
                if i == 0:
                    continue
                p *= p_root if c < 0 else (1.0 - p_root) / i
            if p == 0.0:
                continue
            pairs: set[tuple[int, int]] = set()
            for i in range(n):
                j = choice[i]
                while j >= 0:  # element i must come before every ancestor
                    pairs.add((perm[i], perm[j]))
                    j = choice[j]
            key = frozenset(pairs)
            out[key] = out.get(key, 0.0) + p
    return out


def log2_epsilon(spec: PriorSpec, n_forbiddable: int, n_orderable: int) -> float:
    """log2 of the likelihood of a contradicting execution: the authors' -4 (m + n + n(n-1)/2)."""
    if spec.log2_epsilon is not None:
        return spec.log2_epsilon
    m = n_forbiddable if spec.p_forbid > 0 else 0
    return -4.0 * (m + n_orderable + n_orderable * (n_orderable - 1) / 2)
