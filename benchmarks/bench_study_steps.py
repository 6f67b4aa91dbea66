"""Seconds per learner step of one study participant at n objects, through the study server's own path.

    .venv/bin/python benchmarks/bench_study_steps.py [--sizes 7,8,10] [--seed 1]

The participant (the study's default protocol: 2 demonstrations, 3 active queries, 3 tests, prior
chains-2020-sat) teaches a fixed task: objects 0, 1 and 2 placed, 0 before 1, object 3 never. Each robot turn is
core.session.next_step, as the server's planner makes it (the learner seam: the exact learner past five objects),
timed from a cold cache. Then the views of the final belief that the dashboard and beliefs.csv show: entropy,
expected similarity to the task and the MAP formula. Run `uptime` beside it: the machine's load changes the figures.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from backend.core import learner_seam as seam  # noqa: E402
from backend.core import session as core  # noqa: E402
from backend.core.domain import get_domain, objects_task  # noqa: E402

TRUTH = "F(o0) & F(o1) & F(o2) & (!o1 U o0) & G(!o3)"
DEMONSTRATIONS = (("o0", "o1", "o2"), ("o2", "o0", "o1", "o4"))


def acceptable(trace: tuple[frozenset[str], ...]) -> bool:
    """TRUTH on a trace."""
    first: dict[str, int] = {}
    for t, state in enumerate(trace):
        for p in state:
            first.setdefault(p, t)
    return {"o0", "o1", "o2"} <= set(first) and "o3" not in first and first["o0"] <= first["o1"]


def run(n: int, seed: int) -> None:
    """Print each step's seconds at n objects."""
    task = objects_task(tuple(f"o{i}" for i in range(n)))
    domain = get_domain(task)
    state = core.start(core.SessionConfig(task=task, n_practice=0, seed=seed))
    for demonstration in DEMONSTRATIONS:
        state = core.observe(state, "demonstration", domain.trace_of(demonstration))
    print(f"n = {n} ({seam.path_of(task)} learner)", flush=True)
    while state.phase != "done":
        started = time.perf_counter()
        step = core.next_step(state)
        seconds = time.perf_counter() - started
        assert step.robot_execution is not None
        trace = step.robot_execution.trace
        print(f"  {step.kind} {step.index + 1}: {seconds:6.2f} s  P(acceptable) {step.p_acceptable:.3f}  "
              f"{' '.join(step.robot_execution.events) or '(nothing)'}", flush=True)
        state = core.observe(state, step.kind, trace, acceptable(trace))
    c = state.config
    belief = seam.belief_after(task, c.prior, 0.0, core.learning_verdicts(state))
    truth = domain.clause_space.mask_of_formula(TRUTH)
    for name, ask in (("entropy", lambda: belief.entropy), ("similarity", lambda: belief.similarity(truth)),
                      ("MAP", lambda: belief.map_probability)):
        started = time.perf_counter()
        value = ask()
        print(f"  final {name}: {time.perf_counter() - started:6.2f} s  ({value:.4f})", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="7,8,10", help="comma-separated object counts (2-10)")
    parser.add_argument("--seed", type=int, default=1, help="the session's seed")
    args = parser.parse_args()
    for n in (int(x) for x in args.sizes.split(",")):
        run(n, args.seed)


if __name__ == "__main__":
    main()
