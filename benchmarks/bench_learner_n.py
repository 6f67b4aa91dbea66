"""One participant's whole learner compute at n objects: 2 demonstrations, 3 active queries and updates, 3 test plans.

    .venv/bin/python benchmarks/bench_learner_n.py [--sizes 5,8,10] [--repeats 3] [--summaries]
    .venv/bin/python benchmarks/bench_learner_n.py --teacher random --sizes 8,10 --repeats 10

The fixed teacher knows a task over the first objects (the first three placed in order, the last object
never placed) and labels each query by it. ``--teacher random`` draws each participant's task from the
prior instead (satisfiable, seeded by the repeat) and demonstrates it as the simulation experiments do
(the required objects in a uniformly drawn valid order): a harder case, with more objects that may
come first. At every size the exact factorised learner does the work (posterior by inclusion-exclusion,
branch-and-bound queries and min-regret plans); at five objects the enumerating learner does the same
protocol too, for comparison. Every participant starts from a fresh posterior and an empty MAP memo.
Prints the median CPU seconds (and wall seconds) per participant, the load average, and the process's
peak resident memory. Targets: < 1 s at n = 8, < 5 s at n = 10, < 1 GiB.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.core.belief import Belief  # noqa: E402
from backend.core.exact.learner import posterior_after  # noqa: E402
from backend.core.exact.mapping import clear_memo  # noqa: E402
from backend.core.exact.objects import objects_domain  # noqa: E402
from backend.core.exact.posterior import Datum  # noqa: E402
from backend.core.exact.search import best_execution  # noqa: E402
from backend.core.hypotheses import build_space  # noqa: E402
from backend.core.queries import active_query, plan_execution  # noqa: E402

PRIOR = "chains-2020-sat"


def acceptable(names: tuple[str, ...], events: tuple[str, ...]) -> bool:
    """The teacher's task: the first three objects placed, in order; the last one never."""
    a, b, c = names[:3]
    return all(x in events for x in (a, b, c)) and events.index(a) < events.index(b) < events.index(c) \
        and names[-1] not in events


def demonstrations(names: tuple[str, ...]) -> list[tuple[str, ...]]:
    """Two acceptable demonstrations: the ordered three, then with one optional object in between."""
    return [names[:3], (names[0], names[3], names[1], names[2])]


def factorised_participant(names: tuple[str, ...], teacher: str = "fixed",
                           seed: int = 0) -> tuple[float, float, list[str]]:
    """CPU and wall seconds of the factorised learner's compute for one participant, and a log of what it did."""
    domain = objects_domain(names)
    accepts, demos = _teacher(names, teacher, seed)
    started, wall = time.process_time(), time.perf_counter()
    post = posterior_after(domain, PRIOR, [(domain.trace_of(d), True) for d in demos])
    voc = post.prior.vocabulary
    log = []
    for _ in range(3):
        q = best_execution(post, names, "active")
        ok = accepts(q.events)
        log.append(f"query {','.join(q.events) or '-'} P={q.p_acceptable:.3f} {'ok' if ok else 'no'}")
        post = post.observe(Datum(voc.of_events(q.events), ok))
    for _ in range(3):
        plan = best_execution(post, names, "min-regret")
        log.append(f"plan {','.join(plan.events)} P={plan.p_acceptable:.3f} proven={plan.proven}")
    return time.process_time() - started, time.perf_counter() - wall, log


def _teacher(names: tuple[str, ...], teacher: str, seed: int) -> tuple[Any, list[tuple[str, ...]]]:
    """The teacher's verdict function and the two demonstrations (drawn outside the timed part)."""
    if teacher == "fixed":
        return (lambda events: acceptable(names, events)), demonstrations(names)
    from backend.core.exact.learner import prior_posterior
    from backend.experiments.exact_run import _demonstration, _truth

    domain = objects_domain(names)
    prior = prior_posterior(domain, PRIOR)
    rng = np.random.default_rng(seed)
    truth = _truth(prior, rng)
    voc = prior.prior.vocabulary
    demos = [tuple(_demonstration(domain, prior, truth, rng).events) for _ in range(2)]
    return (lambda events: truth.within(voc.of_events(events))), demos


def enumerated_participant(names: tuple[str, ...]) -> float:
    """CPU seconds of the enumerating learner's compute for the same protocol (space built beforehand)."""
    domain = objects_domain(names)
    space = build_space(domain, PRIOR)
    rng = np.random.default_rng(0)
    started = time.process_time()
    belief = Belief.prior(space)
    for d in demonstrations(names):
        belief = belief.observe(domain.trace_of(d), True)
    for _ in range(3):
        execution, _ = active_query(belief, rng)
        belief = belief.observe(execution.trace, acceptable(names, execution.events))
    for _ in range(3):
        plan_execution(belief, rng=rng)
    return time.process_time() - started


def summaries(names: tuple[str, ...]) -> str:
    """Seconds of the MAP formula, the expected similarity and 100 exact samples after five labelled executions."""
    from backend.core.clauses import Clause
    from backend.core.exact.mapping import map_formula
    from backend.core.exact.sampling import sample_formulas
    from backend.core.exact.similarity import expected_similarity

    domain = objects_domain(names)
    a, b, c, d = names[:4]
    data = [((a, b, c), True), ((a, d, b, c), True), ((b, a, c), False), ((a, b, c, names[-1]), False),
            ((a, b, c, d), True)]
    post = posterior_after(domain, PRIOR, [(domain.trace_of(e), ok) for e, ok in data])
    truth = [Clause("F", a), Clause("F", b), Clause("F", c), Clause("U", a, b), Clause("U", b, c),
             Clause("G", names[-1])]
    out = []
    for label, work in (("MAP", lambda: map_formula(post)), ("similarity", lambda: expected_similarity(post, truth)),
                        ("100 samples", lambda: sample_formulas(post, 100, np.random.default_rng(0)))):
        clear_memo()
        started = time.process_time()
        work()
        out.append(f"{label} {time.process_time() - started:.2f} CPU-s")
    return f"n={n_of(names)} after 5 labelled executions: " + "; ".join(out)


def n_of(names: tuple[str, ...]) -> int:
    """The number of objects."""
    return len(names)


def main() -> None:
    """Print the median per size and the peak memory."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="5,8,10")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--teacher", choices=("fixed", "random"), default="fixed",
                        help="the fixed task (default) or a task drawn from the prior per repeat")
    parser.add_argument("--summaries", action="store_true",
                        help="also time the MAP formula, the expected similarity and 100 samples")
    args = parser.parse_args()
    for n in (int(s) for s in args.sizes.split(",")):
        names = tuple(f"o{i}" for i in range(n))
        if args.summaries:
            print("  " + summaries(names), flush=True)
        if args.repeats <= 0:
            continue
        times, walls = [], []
        for r in range(args.repeats):
            clear_memo()
            seconds, wall, log = factorised_participant(names, args.teacher, r)
            times.append(seconds)
            walls.append(wall)
            print(f"  n={n} run {r + 1}/{args.repeats}: {seconds:.2f} CPU-s ({wall:.2f} s wall), load "
                  f"{os.getloadavg()[0]:.1f}", flush=True)
            if args.teacher == "random":
                print("    " + "; ".join(log), flush=True)
        if args.teacher == "fixed":
            print(f"  n={n} " + "; ".join(log))
        line = (f"n={n:2d}  factorised: median {statistics.median(times):.2f} CPU-s per participant (max "
                f"{max(times):.2f}; wall median {statistics.median(walls):.2f} s)")
        if n == 5 and args.teacher == "fixed":
            enum = [enumerated_participant(names) for _ in range(args.repeats)]
            line += f"  enumerating: median {statistics.median(enum):.2f} CPU-s"
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{line}  (peak RSS so far {peak:.0f} MiB)", flush=True)


if __name__ == "__main__":
    main()
