"""The teacher model fitted from a pilot's export: its verdict-flip rate and its demonstration mode.

The flip rate is the share of query verdicts that contradict the task's ground truth. The demonstration mode is
the one of core.teachers.DEMO_MODES under which the pilot's demonstrations are most likely: each mode's
distribution over demonstrations (the ordered objects placed) is estimated from DRAWS demonstrations of the very
teacher the simulation would use, mixed with a lapse (LAPSE of the mass spread evenly over every order of every
subset of the objects, so a demonstration no mode would give does not rule a mode out), and the modes are
compared by the summed log-likelihood. A tie (on the paper's Task 1, which requires every object, "required-only"
and "uniform" give the same orders) goes to the earlier mode of DEMO_MODES, the authors' demonstrator first.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..core.domain import Domain, get_domain
from ..core.teachers import DEMO_MODES, SimulatedTeacher
from .replay import Export, read_export, sessions

DRAWS = 1000
LAPSE = 0.05


@dataclass(frozen=True)
class DemoModeFit:
    """The most likely demonstration mode, the demonstrations it rests on and each mode's log-likelihood."""

    mode: str
    demonstrations: int
    log_likelihood: dict[str, float]


def fitted_flip_rate(export_path: Path | str) -> tuple[float, int]:
    """(flip rate, verdicts): the share of a pilot's query verdicts that contradict the task's ground truth."""
    export = read_export(export_path)
    space = get_domain("dinner").clause_space
    wrong = total = 0
    for truth_text, row in _rows_with_truth(export, "query"):
        trace = [frozenset(s) for s in json.loads(row["trace"])]
        correct = (space.mask_of_formula(truth_text) & ~space.sat_mask(trace)) == 0
        total += 1
        wrong += int((row["acceptable"] in ("True", "true", "1")) != correct)
    if total == 0:
        raise ValueError(f"{export_path} has no query verdicts on a task with a ground truth; a pilot with Active "
                         "or Random participants is needed to fit the flip rate")
    return min(wrong / total, 0.49), total


def fitted_demo_mode(export_path: Path | str) -> DemoModeFit:
    """The demonstration mode under which the pilot's demonstrations (on tasks with a ground truth) are likeliest."""
    export = read_export(export_path)
    domain = get_domain("dinner")
    space = domain.clause_space
    lapse = LAPSE / _sequence_count(len(domain.orderable))
    totals = dict.fromkeys(DEMO_MODES, 0.0)
    n = 0
    for truth_text, row in _rows_with_truth(export, "demonstration"):
        placed = placements(json.loads(row["trace"]))
        truth = space.mask_of_formula(truth_text)
        n += 1
        for mode in DEMO_MODES:
            totals[mode] += math.log((1 - LAPSE) * _frequencies(domain, truth, mode).get(placed, 0.0) + lapse)
    if n == 0:
        raise ValueError(f"{export_path} has no demonstrations on a task with a ground truth to fit the "
                         "demonstration mode from")
    best = max(DEMO_MODES, key=lambda mode: totals[mode])
    return DemoModeFit(best, n, {mode: round(value, 3) for mode, value in totals.items()})


def placements(trace: list[list[str]]) -> tuple[str, ...]:
    """The objects placed along a trace, in order (a state that adds nothing, a failed move, adds none)."""
    out: list[str] = []
    for before, after in zip(trace, trace[1:], strict=False):
        out += sorted(set(after) - set(before))
    return tuple(out)


def _rows_with_truth(export: Export, kind: str) -> Iterator[tuple[str, dict[str, str]]]:
    """(ground truth, row) of every beliefs.csv row of this record kind on a task that has a ground truth."""
    for (_, task_index), rows in sessions(export).items():
        truth_text = export.study["tasks"][task_index].get("ground_truth")
        if truth_text is None:
            continue
        for row in rows:
            if row["record_kind"] == kind:
                yield truth_text, row


@lru_cache(maxsize=64)
def _frequencies(domain: Domain, truth: int, mode: str) -> dict[tuple[str, ...], float]:
    """How often the simulated teacher of this mode places each sequence of objects, over DRAWS demonstrations."""
    teacher = SimulatedTeacher(domain, truth, demo_mode=mode)
    rng = np.random.default_rng([truth % (2**32), DEMO_MODES.index(mode)])
    draws = 1 if mode == "fixed" else DRAWS  # "fixed" repeats one demonstration: one draw is its distribution
    counts = Counter(teacher.demonstrate(rng).events for _ in range(draws))
    return {events: count / draws for events, count in counts.items()}


def _sequence_count(n_objects: int) -> int:
    """Every order of every subset of n objects (the empty one included)."""
    return sum(math.perm(n_objects, k) for k in range(n_objects + 1))
