"""Learner speed on the dinner table with the faithful 2020 prior (513,024 hypotheses).

Prints medians of several runs for: the batch posterior from 2 demonstrations, one incremental
update, one active query and one min-regret plan, and the ratio to a brute-force query that
scores each of the 326 executions separately. Every call works on a fresh belief object (the same
log weights in a new Belief), so nothing cached on a belief (its probabilities, the executions'
acceptance that queries and plans share) is reused from an earlier call: each figure is what the
first query or plan of a new belief costs. Targets on 2 cores: update < 20 ms, query and
plan < 50 ms. Run: python benchmarks/bench_core.py [--repeats N] [--prior NAME]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from itertools import permutations
from typing import Callable

import numpy as np

from tableteach.core.belief import Belief
from tableteach.core.domain import get_domain
from tableteach.core.executions import execution_graph
from tableteach.core.hypotheses import get_space
from tableteach.core.queries import active_query, plan_execution

DEMOS = [
    ("dinner_plate", "small_plate", "bowl", "fork", "knife"),
    ("knife", "dinner_plate", "small_plate", "fork", "bowl"),
]
QUERY = ("fork", "dinner_plate", "bowl")


def median_ms(fn: Callable[[], object], repeats: int) -> tuple[float, float]:
    """Median wall and CPU time of fn in milliseconds."""
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        fn()
        cpu.append((time.process_time() - start_cpu) * 1000)
        wall.append((time.perf_counter() - start) * 1000)
    return statistics.median(wall), statistics.median(cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--prior", default="chains-2020")
    args = parser.parse_args()

    domain = get_domain("dinner")
    start = time.perf_counter()
    space = get_space("dinner", args.prior)
    execution_graph(domain)
    print(f"prior {args.prior}: {space.size:,} hypotheses, enumerated in {(time.perf_counter() - start) * 1000:.0f} ms")
    traces = [domain.trace_of(d) for d in DEMOS]

    def batch() -> Belief:
        b = Belief.prior(space).observe(traces[0], True).observe(traces[1], True)
        _ = b.probs
        return b

    belief = batch()
    query_trace = domain.trace_of(QUERY)

    def fresh() -> Belief:
        """The same posterior as a new object: nothing cached on it yet."""
        return Belief(space, belief.log_weights)

    def update() -> None:
        _ = fresh().observe(query_trace, False).probs

    rng = np.random.default_rng(0)
    all_traces = [domain.trace_of(o) for k in range(6) for o in permutations(domain.propositions, k)]

    def brute_force_query() -> None:
        b = fresh()
        p = [b.p_acceptable(t) for t in all_traces]
        int(np.argmin(np.abs(2 * np.array(p) - 1)))

    brute = "brute-force query (326 executions scored one by one)"
    results = {
        "batch posterior (2 demos)": median_ms(batch, args.repeats),
        "incremental update (1 execution)": median_ms(update, args.repeats),
        "active query": median_ms(lambda: active_query(fresh(), rng), args.repeats),
        "min-regret plan": median_ms(lambda: plan_execution(fresh(), "min-regret", rng), args.repeats),
        brute: median_ms(brute_force_query, 3),
    }
    targets = {"incremental update (1 execution)": 20, "active query": 50, "min-regret plan": 50}
    print(f"median of {args.repeats} runs (3 for the brute force), each call on a fresh belief (no cached "
          "probabilities or acceptance):")
    print(f"  {'operation':<55} {'wall':>9}    {'CPU':>9}")
    for name, (ms, cpu_ms) in results.items():
        target = (f"  (target < {targets[name]} ms: {'met' if ms < targets[name] else 'MISSED'})"
                  if name in targets else "")
        print(f"  {name:<55} {ms:9.2f} ms {cpu_ms:9.2f} ms{target}")
    ratio = results[brute][0] / results["active query"][0]
    print(f"  active query is {ratio:.0f}x faster than scoring executions one by one")
    print(f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
