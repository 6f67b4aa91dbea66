"""Active-vs-0.80 investigation: Active whose queries end where the belief's reward machine is decided.

    python scripts/investigations/gap_terminal_queries.py

Same runs as the default synthetic sweep (seed 0, 200 runs, n_query 6, the random streams of
simulate_run). A candidate query is an execution summary at which every formula of the
belief's support (p > 1e-6) is decided (violated, or no pending F or order clause) and that is
reachable through an undecided parent: the authors' episodes have no free stop and end there.
Prints Active's median and mean final similarity at n_query 3 and 6 as JSON.
"""

import json
import time

import numpy as np
from tableteach.core.belief import Belief
from tableteach.core.domain import get_domain
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import get_space
from tableteach.core.puns import node_acceptance
from tableteach.core.queries import rollout
from tableteach.core.teachers import SimulatedTeacher
from tableteach.experiments.settings import ExperimentSettings
from tableteach.experiments.simulate import draw_truth

settings = ExperimentSettings(domain="synthetic", runs=200, n_query=(6,), seed=0)
space = get_space("synthetic", settings.prior)
domain = get_domain("synthetic")
cs = domain.clause_space
graph = execution_graph(domain)
n = graph.n_nodes
viol = np.zeros(n, dtype=np.uint64)
pend = np.zeros(n, dtype=np.uint64)
for i, ev in enumerate(graph.events):
    first = {p: t for t, p in enumerate(ev)}
    v = pd = 0
    for b, c in enumerate(cs.clauses):
        if c.kind == "G":
            v |= (1 << b) if c.first in first else 0
        elif c.kind == "F":
            pd |= 0 if c.first in first else (1 << b)
        else:
            a, bb = first.get(c.first), first.get(c.second)
            if a is None and bb is None:
                pd |= 1 << b
            elif bb is not None and (a is None or bb < a):
                v |= 1 << b
    viol[i], pend[i] = v, pd
parents = [[] for _ in range(n)]
for i in range(n):
    for c in graph.child[i]:
        if c >= 0:
            parents[c].append(i)

def terminal_candidates(belief: Belief) -> np.ndarray:
    """Execution summaries where the belief's reward machine is decided, reached through an undecided parent."""
    support = space.masks[belief.probs > 1e-6]
    decided = np.ones(n, dtype=bool)
    for start in range(0, n, 512):
        sl = slice(start, start + 512)
        d = ((support[None, :] & viol[sl, None]) != 0) | ((support[None, :] & pend[sl, None]) == 0)
        decided[sl] = d.all(axis=1)
    ok = decided.copy()
    for i in np.flatnonzero(decided):
        if i != 0 and all(decided[j] for j in parents[i]):
            ok[i] = False  # every way in has already ended the episode
    return np.flatnonzero(ok)

out = {3: [], 6: []}
t0 = time.time()
for run in range(settings.runs):
    streams = np.random.SeedSequence([settings.seed, run]).spawn(7)
    truth = draw_truth(settings, space, np.random.default_rng(streams[0]))
    teacher = SimulatedTeacher(domain, truth)
    demo_rng = np.random.default_rng(streams[1])
    belief = Belief.prior(space)
    for _ in range(2):
        belief = belief.observe(teacher.demonstrate(demo_rng).trace, True)
    rng, trng = np.random.default_rng(streams[3]), np.random.default_rng(streams[2])
    for q in range(1, 7):
        cand = terminal_candidates(belief)
        score = np.abs(2 * node_acceptance(belief)[cand] - 1)
        tied = cand[score <= score.min() + 1e-12]
        node = int(tied[rng.integers(tied.size)])
        ex = rollout(domain, graph.events[node], rng)
        belief = belief.observe(ex.trace, teacher.assess(ex.trace, trng))
        if q in out:
            out[q].append(belief.similarity(truth))
medians = {f"active@{q}": round(float(np.median(v)), 4) for q, v in out.items()}
means = {f"active_mean@{q}": round(float(np.mean(v)), 4) for q, v in out.items()}
print(json.dumps({"seconds": round(time.time() - t0), **medians, **means}))
