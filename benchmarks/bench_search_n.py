"""How often the branch-and-bound search finds the exhaustive optimum, for n objects (n <= 7).

    .venv/bin/python benchmarks/bench_search_n.py [--sizes 5,6,7] [--trials 10,5,2] [--branch-and-bound]

Each trial: two demonstrations and one labelled random execution drawn at random, under chains-2020-sat;
every execution (sum of n!/(n-k)!: 326, 1,957, 13,700) is scored exactly with the factorised learner, and
the search's active query (default budget) and min-regret plan are compared with the best scores
(|2P - 1| smallest; P largest) within 1e-9. Prints the share of trials where each reached the optimum,
the median CPU seconds of search and of exhaustive scoring, and the load average. ``--branch-and-bound``
makes the active query search even where the moves keep few enough executions to score them all.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from itertools import permutations
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.core.exact.batch import of_events  # noqa: E402
from backend.core.exact.learner import posterior_after  # noqa: E402
from backend.core.exact.objects import objects_domain  # noqa: E402
from backend.core.exact import search  # noqa: E402
from backend.core.exact.search import best_execution  # noqa: E402


def all_executions(names: tuple[str, ...]) -> list[tuple[str, ...]]:
    """Every ordered subset of the objects, the empty one included."""
    return [p for k in range(len(names) + 1) for p in permutations(names, k)]


def trial(names: tuple[str, ...], rng: np.random.Generator) -> tuple[bool, bool, float, float, float]:
    """(active optimal, plan optimal, search seconds, exhaustive seconds, active's |2P-1| gap) for one data set."""
    domain = objects_domain(names)
    executions = all_executions(names)
    picks = [executions[i] for i in rng.choice(len(executions), 3)]
    data = [(domain.trace_of(picks[0]), True), (domain.trace_of(picks[1]), True),
            (domain.trace_of(picks[2]), bool(rng.random() < 0.5))]
    post = posterior_after(domain, "chains-2020-sat", data)
    started = time.process_time()
    query = best_execution(post, names, "active")
    plan = best_execution(post, names, "min-regret")
    searched = time.process_time() - started
    started = time.process_time()
    p = post.p_within(of_events(post.prior.vocabulary, executions))
    exhaustive = time.process_time() - started
    active_ok = abs(2 * query.p_acceptable - 1) <= np.abs(2 * p - 1).min() + 1e-9
    plan_ok = plan.p_acceptable >= p.max() - 1e-9
    gap = abs(2 * query.p_acceptable - 1) - float(np.abs(2 * p - 1).min())
    return bool(active_ok), bool(plan_ok), searched, exhaustive, gap


def main() -> None:
    """Print the optimum rates per size."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="5,6,7")
    parser.add_argument("--trials", default="10,5,2")
    parser.add_argument("--branch-and-bound", action="store_true",
                        help="never score every kept execution for the active query")
    args = parser.parse_args()
    if args.branch_and_bound:
        search.EXHAUSTIVE_ACTIVE = 0
    rng = np.random.default_rng(0)
    sizes = [int(s) for s in args.sizes.split(",")]
    counts = [int(t) for t in args.trials.split(",")]
    for n, trials in zip(sizes, counts, strict=True):
        names = tuple(f"o{i}" for i in range(n))
        results = []
        for t in range(trials):
            results.append(trial(names, rng))
            print(f"  n={n} trial {t + 1}/{trials}: {results[-1]}", flush=True)
        active = sum(r[0] for r in results)
        plans = sum(r[1] for r in results)
        print(f"n={n}: active query optimal in {active}/{trials}, min-regret plan optimal in {plans}/{trials}; "
              f"median search {statistics.median(r[2] for r in results):.2f} s, "
              f"exhaustive {statistics.median(r[3] for r in results):.2f} s; active's median gap in |2P - 1| "
              f"{statistics.median(r[4] for r in results):.3f} (CPU seconds; load {os.getloadavg()[0]:.1f})",
              flush=True)


if __name__ == "__main__":
    main()
