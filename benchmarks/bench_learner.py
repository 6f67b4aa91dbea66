"""One participant's whole learner compute as a study makes it: 2 demonstrations, 3 queries and updates, 3 tests.

    .venv/bin/python benchmarks/bench_learner.py [--repeats 30] [--task task1] [--prior chains-2020-sat]

Each run is one Active session on the dinner table driven through backend.core.session the way the server
drives it (services.teaching records each step with ``session.observe``; services.planning plans each robot
turn with ``session.next_step``): a practice, two demonstrations, three active queries each assessed by a
simulated teacher who knows the task and the update they cause, then three min-regret test plans. Every run
starts from a fresh state: the session module's caches (beliefs by data prefix, planned steps) are cleared
first, and every belief is a new object, so nothing is reused from an earlier run. What a server process
builds once and keeps (the enumerated hypothesis space and the execution graph) is built before timing.
Prints the median wall and CPU time of the runs. Target: < 50 ms per participant.

``learner_seconds_per_participant`` is importable without the web or the database (benchmarks/bench_scale.py
reports it as ``learner_s``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from backend.core import session  # noqa: E402
from backend.core.domain import DINNER_TASK_FORMULAS, get_domain  # noqa: E402
from backend.core.executions import execution_graph  # noqa: E402
from backend.core.hypotheses import get_space  # noqa: E402
from backend.core.priors import DEFAULT_PRIOR  # noqa: E402
from backend.core.teachers import SimulatedTeacher  # noqa: E402

TARGET_MS = 50.0


def clear_learner_caches() -> None:
    """Forget every belief and planned step the session module has cached (a fresh process's state)."""
    session.belief_after.cache_clear()
    session.noisy_belief_after.cache_clear()
    session.next_step.cache_clear()


def _teacher(task: str) -> SimulatedTeacher:
    domain = get_domain("dinner")
    return SimulatedTeacher(domain, domain.clause_space.mask_of_formula(DINNER_TASK_FORMULAS[task]))


def run_participant(seed: int = 0, task: str = "task1", prior: str = DEFAULT_PRIOR) -> list[str]:
    """One whole Active session's learner work (untimed); returns a log of the robot's turns."""
    teacher = _teacher(task)
    domain = teacher.domain
    rng = np.random.default_rng(seed)
    state = session.start(session.SessionConfig(task="dinner", prior=prior, protocol="active", seed=seed))
    log: list[str] = []
    while True:
        step = session.next_step(state)
        if step.kind == "done":
            return log
        if step.kind in ("practice", "demonstration"):
            trace = domain.trace_of(teacher.demonstrate(rng).events)
            state = session.observe(state, step.kind, trace)
            continue
        execution = step.robot_execution
        assert execution is not None, f"a {step.kind} comes with the robot's execution"
        verdict = teacher.assess(execution.trace, rng)
        log.append(f"{step.kind} {','.join(execution.events) or '-'} P={step.p_acceptable:.3f} "
                   f"{'ok' if verdict else 'no'}")
        state = session.observe(state, step.kind, list(execution.trace), verdict)


def warm_up(prior: str = DEFAULT_PRIOR) -> None:
    """Build what a server process builds once: the hypothesis space, the execution graph and their tables."""
    space = get_space("dinner", prior)
    execution_graph(space.domain)
    clear_learner_caches()
    run_participant(0, prior=prior)


def time_participants(
    repeats: int = 30, task: str = "task1", prior: str = DEFAULT_PRIOR
) -> tuple[list[float], list[float]]:
    """Wall and CPU seconds of ``repeats`` sessions (seeds 0, 1, ...), each from a fresh state."""
    warm_up(prior)
    wall, cpu = [], []
    for seed in range(repeats):
        clear_learner_caches()
        w, c = time.perf_counter(), time.process_time()
        run_participant(seed, task, prior)
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    clear_learner_caches()
    return wall, cpu


def learner_seconds_per_participant(repeats: int = 30, task: str = "task1", prior: str = DEFAULT_PRIOR) -> float:
    """Median wall seconds of one participant's whole learner compute (fresh state each run)."""
    wall, _ = time_participants(repeats, task, prior)
    return statistics.median(wall)


def main() -> None:
    """Print the medians and whether the target holds."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--task", choices=sorted(DINNER_TASK_FORMULAS), default="task1")
    parser.add_argument("--prior", default=DEFAULT_PRIOR)
    args = parser.parse_args()
    space = get_space("dinner", args.prior)
    print(f"dinner {args.task}, prior {args.prior} ({space.size:,} hypotheses), Active: "
          "2 demonstrations, 3 queries and updates, 3 test plans")
    print("each run from a fresh state (session caches cleared, new beliefs); space and graph built beforehand")
    wall, cpu = time_participants(args.repeats, args.task, args.prior)
    print("seed 0: " + "; ".join(run_participant(0, args.task, args.prior)))
    clear_learner_caches()
    median_ms = 1000 * statistics.median(wall)
    verdict = "met" if median_ms < TARGET_MS else "MISSED"
    print(f"median of {args.repeats} runs: {median_ms:.1f} ms wall (min {1000 * min(wall):.1f}, max "
          f"{1000 * max(wall):.1f}), {1000 * statistics.median(cpu):.1f} ms CPU"
          f"  (target < {TARGET_MS:.0f} ms: {verdict})")
    print(f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
