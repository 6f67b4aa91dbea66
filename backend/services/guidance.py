"""What the participant page tells a participant beyond the protocol: which objects a task requires, how far
through the study they are (with a time estimate), and what the robot learned in words a lay reader follows."""

from __future__ import annotations

import math
from typing import Any

from ..core import session as core
from ..core.clauses import Clause, humanize, join_words
from ..core.domain import get_domain

# One placement by the MuJoCo robot at 1x takes about 5.6 s of motion (a 5-object execution about 28 s).
PLACEMENT_SECONDS = 5.6
OBJECTS_PER_EXECUTION = 4  # a typical robot turn places four of the five objects
THINK_SECONDS = {"practice": 30.0, "demonstration": 20.0, "query": 12.0, "test": 10.0}
QUESTIONNAIRE_SECONDS = 120.0
INTRO_SECONDS = 60.0  # reading one task's instructions and goal picture
BEFORE_TASKS = ("consent", "instructions", "quiz")  # stages before the first task (no step done yet)
ENDED = ("done", "withdrawn", "screened_out")  # nothing left to do


def required_objects(task: dict[str, Any], domain: str = "dinner") -> list[str]:
    """Objects the task's ground truth says must end up on the table (none if the ground truth is unknown)."""
    formula = task.get("ground_truth")
    if not formula:
        return []
    space = get_domain(domain).clause_space
    return [c.first for c in space.clauses_of(space.mask_of_formula(formula)) if c.kind == "F"]


def step_counts(config: core.SessionConfig) -> list[tuple[str, int]]:
    """The steps of one task session by kind, in order: [(kind, how many)]."""
    return [("practice", config.n_practice), ("demonstration", config.demonstrations_needed),
            ("query", config.queries_needed), ("test", config.n_tests)]


def _step_seconds(kind: str, speed: float) -> float:
    objects = 5 if kind in ("practice", "demonstration") else OBJECTS_PER_EXECUTION
    return THINK_SECONDS[kind] + objects * PLACEMENT_SECONDS / max(speed, 0.1)


def progress(configs: list[core.SessionConfig], stage: str, task_index: int, step: dict[str, Any] | None,
             *, speed: float, questionnaire: bool) -> dict[str, Any]:
    """Steps done of all steps in the study, and about how many minutes are left (rounded up)."""
    steps: list[tuple[int, str, int]] = [(i, kind, j) for i, c in enumerate(configs)
                                         for kind, n in step_counts(c) for j in range(n)]
    order = ("practice", "demonstration", "query", "test")
    if stage in BEFORE_TASKS:
        done = 0
    elif stage == "task" and step is not None:
        here = (task_index, order.index(step["kind"]) if step["kind"] in order else len(order), step["index"])
        done = sum(1 for i, kind, j in steps if (i, order.index(kind), j) < here)
    else:
        done = len(steps)
    left = sum(_step_seconds(kind, speed) for _, kind, _ in steps[done:])
    if stage in (*BEFORE_TASKS, "task"):
        intros_left = len(configs) - (task_index + 1 if stage == "task" else 0)
        left += INTRO_SECONDS * max(intros_left, 0)
    if questionnaire and stage not in ENDED:
        left += QUESTIONNAIRE_SECONDS
    total = len(steps) + (1 if questionnaire else 0)
    finished = done + (1 if stage in ENDED and questionnaire else 0)
    return {"done": finished, "total": total, "minutes_left": 0 if stage in ENDED
            else max(1, math.ceil(left / 60))}


def _chains(orders: list[tuple[str, str]]) -> list[list[str]]:
    """Merge "a before b" pairs into chains a, b, c where the pairs allow (after dropping implied pairs)."""
    pairs = set(orders)
    implied = {(a, c) for a, b in pairs for b2, c in pairs if b == b2 and (a, c) in pairs}
    pairs -= implied
    after: dict[str, list[str]] = {}
    before: dict[str, list[str]] = {}
    for a, b in sorted(pairs):
        after.setdefault(a, []).append(b)
        before.setdefault(b, []).append(a)
    chains: list[list[str]] = []
    used: set[tuple[str, str]] = set()
    for a, b in sorted(pairs):
        if (a, b) in used or (len(before.get(a, [])) == 1 and len(after.get(before[a][0], [])) == 1):
            continue  # a pair inside a chain is reached from the chain's start
        chain = [a, b]
        used.add((a, b))
        while len(after.get(chain[-1], [])) == 1 and len(before.get(after[chain[-1]][0], [])) == 1:
            nxt = after[chain[-1]][0]
            used.add((chain[-1], nxt))
            chain.append(nxt)
        chains.append(chain)
    for a, b in sorted(pairs - used):
        chains.append([a, b])
    return chains


def lay_summary(clauses: list[Clause]) -> str:
    """E.g. "Place the dinner plate, the bowl and the knife. Place the dinner plate before the bowl. Never place
    the small plate." An order involving a forbidden object is left out (it can never come up)."""
    if not clauses:
        return "Any way of setting the table is fine."
    forbidden = [c.first for c in clauses if c.kind == "G"]
    required = [c.first for c in clauses if c.kind == "F" and c.first not in forbidden]
    orders = [(c.first, c.second or "") for c in clauses
              if c.kind == "U" and c.first not in forbidden and c.second not in forbidden]
    sentences = []
    if required:
        sentences.append("Place " + join_words([f"the {humanize(p)}" for p in required]) + ".")
    for chain in _chains(orders):
        names = [f"the {humanize(p)}" for p in chain]
        if len(chain) == 2:
            sentences.append(f"Place {names[0]} before {names[1]}.")
        else:
            sentences.append(f"Place {', then '.join(names)}, in this order.")
    if forbidden:
        sentences.append("Never place " + join_words([f"the {humanize(p)}" for p in forbidden]) + ".")
    return " ".join(sentences) if sentences else "Any way of setting the table is fine."
