"""One participant's whole learner compute at n objects: 2 demonstrations, 3 active queries and updates, 3 test plans.

    .venv/bin/python benchmarks/bench_learner_n.py [--sizes 5,8,10] [--repeats 3] [--summaries]

The teacher knows a fixed task over the first objects (the first three placed in order, the last object
never placed) and labels each query by it. At every size the exact factorised learner does the work
(posterior by inclusion-exclusion, branch-and-bound queries and min-regret plans); at five objects the
enumerating learner (today's) does the same protocol too, for comparison. Prints the median seconds per
participant and the process's peak resident memory. Targets: < 1 s at n = 8, < 5 s at n = 10, < 1 GiB.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.core.belief import Belief  # noqa: E402
from backend.core.exact.learner import posterior_after  # noqa: E402
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


def factorised_participant(names: tuple[str, ...]) -> tuple[float, list[str]]:
    """Seconds of the factorised learner's compute for one participant, and a log of what it did."""
    domain = objects_domain(names)
    started = time.perf_counter()
    post = posterior_after(domain, PRIOR, [(domain.trace_of(d), True) for d in demonstrations(names)])
    voc = post.prior.vocabulary
    log = []
    for _ in range(3):
        q = best_execution(post, names, "active")
        ok = acceptable(names, q.events)
        log.append(f"query {','.join(q.events) or '-'} P={q.p_acceptable:.3f} {'ok' if ok else 'no'}")
        post = post.observe(Datum(voc.of_events(q.events), ok))
    for _ in range(3):
        plan = best_execution(post, names, "min-regret")
        log.append(f"plan {','.join(plan.events)} P={plan.p_acceptable:.3f} proven={plan.proven}")
    return time.perf_counter() - started, log


def enumerated_participant(names: tuple[str, ...]) -> float:
    """Seconds of the enumerating learner's compute for the same protocol (space built beforehand)."""
    domain = objects_domain(names)
    space = build_space(domain, PRIOR)
    rng = np.random.default_rng(0)
    started = time.perf_counter()
    belief = Belief.prior(space)
    for d in demonstrations(names):
        belief = belief.observe(domain.trace_of(d), True)
    for _ in range(3):
        execution, _ = active_query(belief, rng)
        belief = belief.observe(execution.trace, acceptable(names, execution.events))
    for _ in range(3):
        plan_execution(belief, rng=rng)
    return time.perf_counter() - started


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
        started = time.perf_counter()
        work()
        out.append(f"{label} {time.perf_counter() - started:.2f} s")
    return f"n={n_of(names)} after 5 labelled executions: " + "; ".join(out)


def n_of(names: tuple[str, ...]) -> int:
    """The number of objects."""
    return len(names)


def main() -> None:
    """Print the median per size and the peak memory."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="5,8,10")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--summaries", action="store_true",
                        help="also time the MAP formula, the expected similarity and 100 samples")
    args = parser.parse_args()
    for n in (int(s) for s in args.sizes.split(",")):
        names = tuple(f"o{i}" for i in range(n))
        if args.summaries:
            print("  " + summaries(names), flush=True)
        if args.repeats <= 0:
            continue
        times = []
        for r in range(args.repeats):
            seconds, log = factorised_participant(names)
            times.append(seconds)
            print(f"  n={n} run {r + 1}/{args.repeats}: {seconds:.2f} s", flush=True)
        print(f"  n={n} " + "; ".join(log))
        line = f"n={n:2d}  factorised: median {statistics.median(times):.2f} s per participant"
        if n == 5:
            enum = [enumerated_participant(names) for _ in range(args.repeats)]
            line += f"  enumerating: median {statistics.median(enum):.2f} s"
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{line}  (peak RSS so far {peak:.0f} MiB)", flush=True)


if __name__ == "__main__":
    main()
