"""One simulated run of the paper's experiment: Active, Random and Batch on a shared ground truth.

Within a run the three protocols share the ground truth and the first demonstrations (paired
comparison). Each protocol then computes its longest sequence (max n_query queries, or as many
extra demonstrations for Batch) once; the rows for a smaller n_query are prefixes of that same
sequence, which is valid because a query depends only on the belief so far.

Randomness: one numpy SeedSequence per (sweep seed, run index), spawned into independent streams
for the ground truth, the shared demonstrations, the teacher's label noise and each protocol.
A run's rows therefore do not depend on which process computes it or in which order.
"""

from __future__ import annotations

import json
import time
from functools import lru_cache
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..core.belief import Belief
from ..core.domain import synthetic_domain
from ..core.hypotheses import HypothesisSpace, build_space, get_space
from ..core.queries import Execution, active_query, information_gain_query, plan_execution, random_query
from ..core.teachers import SimulatedTeacher, authors_ground_truth, sample_ground_truth
from ..core.session import PROTOCOLS
from .exact_run import simulate_exact_run
from .run_rows import protocol_rows
from .settings import ExperimentSettings

COLUMNS = (
    "run", "seed", "domain", "prior", "protocol", "n_query", "step", "n_executions",
    "entropy", "similarity", "map_similarity", "map_formula", "ground_truth", "test_success", "seconds",
)


@dataclass(frozen=True)
class StepResult:
    """The learner's state after one learning step, summarised by the metrics we record."""

    kind: str
    entropy: float
    similarity: float
    map_similarity: float
    map_formula: str
    seconds: float
    test_success: int | None = None


def experiment_space(settings: ExperimentSettings) -> HypothesisSpace:
    """The enumerated hypothesis space of the sweep's domain (the synthetic one at its requested size)."""
    if settings.task == "synthetic" and (settings.n_waypoints, settings.n_threats) != (5, 5):
        return _sized_synthetic_space(settings.n_waypoints, settings.n_threats, settings.prior)
    return get_space(settings.task, settings.prior)


@lru_cache(maxsize=4)
def _sized_synthetic_space(n_waypoints: int, n_threats: int, prior: str) -> HypothesisSpace:
    return build_space(synthetic_domain(n_waypoints, n_threats), prior)


def draw_truth(settings: ExperimentSettings, space: HypothesisSpace, rng: np.random.Generator) -> int:
    """The run's ground-truth clause mask: fixed, from the prior (satisfiable only) or the authors' sampler."""
    if settings.fixed_truth is not None:
        return space.domain.clause_space.mask_of_formula(settings.fixed_truth)
    if settings.truth_sampler == "authors":
        return authors_ground_truth(space.domain, rng)
    return sample_ground_truth(space, rng)


class _Tester:
    """Whether the robot's test execution (min-regret plan of a belief) satisfies the truth, at chosen steps."""

    def __init__(self, settings: ExperimentSettings, truth: int, seed: np.random.SeedSequence) -> None:
        self.enabled = settings.test_success
        self.finals = {settings.n_demonstrations + n for n in settings.n_query}
        self.truth = truth
        self.seed = seed

    def __call__(self, belief: Belief, n_executions: int, protocol: str) -> int | None:
        """1 or 0 at a final step of some n_query when enabled, else None (not measured)."""
        if not self.enabled or n_executions not in self.finals:
            return None
        # its own stream per (protocol, step): the learner's and teacher's streams stay untouched
        rng = np.random.default_rng([*self.seed.generate_state(2), PROTOCOL_INDEX[protocol], n_executions])
        execution, _ = plan_execution(belief, rng=rng)
        sat = belief.space.domain.clause_space.sat_mask(execution.trace)
        return int((self.truth & ~sat) == 0)


PROTOCOL_INDEX = {protocol: i for i, protocol in enumerate(PROTOCOLS)} | {"shared": len(PROTOCOLS)}


def _step_result(kind: str, belief: Belief, truth: int, seconds: float, metric: str) -> StepResult:
    """A step's metrics against the run's ground truth."""
    return StepResult(
        kind=kind,
        entropy=belief.entropy + 0.0,  # + 0.0 turns -0.0 into 0.0
        similarity=belief.similarity(truth, metric),
        map_similarity=belief.map_similarity(truth, metric),
        map_formula=belief.space.domain.clause_space.text_of(belief.map_mask),
        seconds=seconds,
    )


def _protocol_steps(
    settings: ExperimentSettings,
    protocol: str,
    belief: Belief,
    teacher: SimulatedTeacher,
    n_steps: int,
    learner_rng: np.random.Generator,
    teacher_rng: np.random.Generator,
    truth: int,
    tester: _Tester,
) -> list[StepResult]:
    """The steps a protocol takes after the shared demonstrations."""
    out: list[StepResult] = []
    first = settings.n_demonstrations + 1
    for k in range(n_steps):
        started = time.perf_counter()
        if protocol == "batch":
            demo: Execution = teacher.demonstrate(teacher_rng)
            learner_started = time.perf_counter()
            belief = belief.observe(demo.trace, True)
            seconds = time.perf_counter() - learner_started
            result = _step_result("demonstration", belief, truth, seconds, settings.similarity)
            out.append(replace(result, test_success=tester(belief, first + k, protocol)))
            continue
        if protocol == "active" and settings.active_strategy == "information-gain":
            execution, _ = information_gain_query(belief, learner_rng, settings.learner_flip_rate)
        elif protocol == "active":
            execution, _ = active_query(belief, learner_rng, settings.query_ties)
        else:
            execution, _ = random_query(belief, learner_rng)
        chosen = time.perf_counter()
        verdict = teacher.assess(execution.trace, teacher_rng)
        updating = time.perf_counter()
        belief = belief.observe(execution.trace, verdict, settings.learner_flip_rate)
        seconds = (chosen - started) + (time.perf_counter() - updating)
        result = _step_result("query", belief, truth, seconds, settings.similarity)
        out.append(replace(result, test_success=tester(belief, first + k, protocol)))
    return out


def simulate_run(settings: ExperimentSettings, run: int) -> list[list[Any]]:
    """All rows of one run (every protocol, every n_query, every learning step), in sorted order."""
    if settings.exact_learner:
        return simulate_exact_run(settings, run)
    streams = np.random.SeedSequence([settings.seed, run]).spawn(4 + len(PROTOCOLS))
    truth_rng, demo_rng = np.random.default_rng(streams[0]), np.random.default_rng(streams[1])
    space = experiment_space(settings)
    domain = space.domain
    truth = draw_truth(settings, space, truth_rng)
    teacher = SimulatedTeacher(domain, truth, noise=settings.noise, demo_mode=settings.demo_mode)
    tester = _Tester(settings, truth, streams[3 + len(PROTOCOLS)])  # spawned last: earlier streams unchanged

    started = time.perf_counter()
    belief = Belief.prior(space)
    shared = [replace(_step_result("prior", belief, truth, time.perf_counter() - started, settings.similarity),
                      test_success=tester(belief, 0, "shared"))]
    for _ in range(settings.n_demonstrations):
        demo = teacher.demonstrate(demo_rng)
        started = time.perf_counter()
        belief = belief.observe(demo.trace, True)
        seconds = time.perf_counter() - started
        result = _step_result("demonstration", belief, truth, seconds, settings.similarity)
        shared.append(replace(result, test_success=tester(belief, len(shared), "shared")))

    truth_text = domain.clause_space.text_of(truth)
    rows: list[list[Any]] = []
    for k, protocol in enumerate(PROTOCOLS):
        learner_rng = np.random.default_rng(streams[3 + k])
        # Active and Random replay the same noise stream, so a fallible teacher flips the same
        # query positions in both; Batch's teacher uses the stream for its extra demonstrations.
        teacher_rng = np.random.default_rng(streams[3 + k] if protocol == "batch" else streams[2])
        steps = shared + _protocol_steps(
            settings, protocol, belief, teacher, settings.max_n_query, learner_rng, teacher_rng, truth, tester
        )
        rows.extend(protocol_rows(settings, run, protocol, truth_text, steps))
    return rows


def run_task_json(task: str) -> str:
    """Run one task given as JSON {"settings": {...}, "run": i}; return JSON {"run": i, "rows": [...]}.

    This is the only function that crosses a process boundary (worker pool, Dask): JSON in and
    out, never pickled objects of ours.
    """
    data = json.loads(task)
    settings = ExperimentSettings.from_json(data["settings"])
    run = data["run"]
    if isinstance(run, bool) or not isinstance(run, int) or not 0 <= run < settings.runs:
        raise ValueError(f"run index must be a whole number in [0, {settings.runs}), got {run!r}")
    return json.dumps({"run": run, "rows": simulate_run(settings, run)})


def task_json(settings: ExperimentSettings, run: int) -> str:
    """The JSON task line for one run."""
    return json.dumps({"settings": settings.to_json(), "run": run})
