"""Teaching-session state machine for the protocols Active, Random and Batch.

State is explicit and immutable: the configuration (with its seed) and every recorded execution.
``next_step`` says what happens next (and, for robot turns, which execution the robot performs);
``observe`` records what happened and returns the new state. The robot's executions are derived
from the seed and the data so far, so a reloaded session proposes exactly the same next query.
The belief is recomputed from the recorded executions (cached, and incremental: each execution
extends the cached belief of the executions before it). ``to_json``/``from_json`` round-trip.

Phases: practice -> demonstration -> query (Active/Random only) -> test -> done.
Batch replaces the queries by as many extra demonstrations.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from typing import Any, Literal

import numpy as np

from .belief import Belief, check_flip_rate
from .domain import get_domain
from .enumerated_beliefs import Trace, Verdicts, belief_after, noisy_belief_after
from .priors import DEFAULT_PRIOR, NAMED_PRIORS
from .puns import CRITERIA
from .learner_seam import robot_plan, robot_query
from .queries import Execution

PROTOCOLS = ("active", "random", "batch")
PHASES = ("practice", "demonstration", "query", "test", "done")
StepKind = Literal["practice", "demonstration", "query", "test", "done"]
SCHEMA_VERSION = 1



class ProtocolError(ValueError):
    """An event that the protocol does not allow now; names what was expected instead."""


@dataclass(frozen=True)
class SessionConfig:
    """Everything that fixes a teaching session's behaviour, the seed included."""

    task: str = "dinner"
    prior: str = DEFAULT_PRIOR
    protocol: str = "active"
    n_practice: int = 1
    n_demonstrations: int = 2
    n_queries: int = 3
    n_tests: int = 3
    criterion: str = "min-regret"
    seed: int = 0
    flip_rate: float = 0.0  # the learner's assumed verdict-flip probability (0: the authors' learner)

    def __post_init__(self) -> None:
        get_domain(self.task)
        if self.prior not in NAMED_PRIORS:
            raise ValueError(f"unknown prior {self.prior!r}; expected one of {', '.join(NAMED_PRIORS)}")
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"unknown protocol {self.protocol!r}; expected one of {', '.join(PROTOCOLS)}")
        if self.criterion not in CRITERIA:
            raise ValueError(f"unknown criterion {self.criterion!r}; expected one of {', '.join(CRITERIA)}")
        for name in ("n_practice", "n_demonstrations", "n_queries", "n_tests"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ValueError(f"seed must be a whole number >= 0, got {self.seed!r}")
        check_flip_rate(self.flip_rate, "flip_rate")

    @property
    def demonstrations_needed(self) -> int:
        """Demonstrations in this protocol (Batch adds one per query it does not ask)."""
        return self.n_demonstrations + (self.n_queries if self.protocol == "batch" else 0)

    @property
    def queries_needed(self) -> int:
        """Robot queries in this protocol."""
        return 0 if self.protocol == "batch" else self.n_queries


@dataclass(frozen=True)
class Record:
    """One recorded execution: its kind, its trace and, where there is one, the verdict."""

    kind: StepKind
    trace: Trace
    acceptable: bool | None = None
    proposed: tuple[str, ...] | None = None


@dataclass(frozen=True)
class Step:
    """What the session expects next; for robot turns, the execution the robot performs."""

    kind: StepKind
    index: int
    total: int
    robot_execution: Execution | None = None
    p_acceptable: float | None = None

    def to_json(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "kind": self.kind,
            "index": self.index,
            "total": self.total,
            "robot_execution": None if self.robot_execution is None else self.robot_execution.to_json(),
            "p_acceptable": self.p_acceptable,
        }


@dataclass(frozen=True)
class SessionState:
    """A teaching session: its configuration and its records so far."""

    config: SessionConfig
    records: tuple[Record, ...] = field(default_factory=tuple)

    def count(self, kind: StepKind) -> int:
        """How many records of a kind exist."""
        return sum(1 for r in self.records if r.kind == kind)

    @property
    def learning_records(self) -> tuple[Record, ...]:
        """Demonstrations and assessed queries, in order: the data the belief is built from."""
        return tuple(r for r in self.records if r.kind in ("demonstration", "query"))

    @property
    def phase(self) -> StepKind:
        """The current phase."""
        c = self.config
        if self.count("practice") < c.n_practice:
            return "practice"
        if self.count("demonstration") < c.demonstrations_needed:
            return "demonstration"
        if self.count("query") < c.queries_needed:
            return "query"
        if self.count("test") < c.n_tests:
            return "test"
        return "done"

    # ------------------------------------------------------------ JSON

    def to_json(self) -> str:
        """Serialise to a JSON string (no pickle; safe to store and send)."""
        records = [
            {
                "kind": r.kind,
                "trace": [sorted(s) for s in r.trace],
                "acceptable": r.acceptable,
                "proposed": None if r.proposed is None else list(r.proposed),
            }
            for r in self.records
        ]
        config = asdict(self.config)
        if config["flip_rate"] == 0.0:  # sessions of the authors' learner are stored exactly as before
            del config["flip_rate"]
        return json.dumps({"schema": SCHEMA_VERSION, "config": config, "records": records})

    @staticmethod
    def from_json(text: str) -> "SessionState":
        """Rebuild a session from ``to_json`` output; ValueError names what is malformed."""
        try:
            data = json.loads(text)
            if data.get("schema") != SCHEMA_VERSION:
                raise ValueError(f"unsupported session schema {data.get('schema')!r}; expected {SCHEMA_VERSION}")
            config = SessionConfig(**data["config"])
            records = tuple(
                Record(
                    kind=r["kind"],
                    trace=tuple(frozenset(s) for s in r["trace"]),
                    acceptable=r["acceptable"],
                    proposed=None if r["proposed"] is None else tuple(r["proposed"]),
                )
                for r in data["records"]
            )
        except (KeyError, TypeError, json.JSONDecodeError) as exc:
            raise ValueError(f"malformed session JSON: {exc}") from exc
        return SessionState(config, records)


def start(config: SessionConfig) -> SessionState:
    """A new session with no records."""
    return SessionState(config)


def _rng(config: SessionConfig, kind: str, index: int) -> np.random.Generator:
    """The seeded generator of one robot turn, independent of everything else that happened."""
    return np.random.default_rng([config.seed, PHASES.index(kind), index])  # type: ignore[arg-type]


def learning_data(state: SessionState) -> tuple[tuple[Trace, bool], ...]:
    """The session's demonstrations and assessed queries as (trace, acceptable), in order."""
    return tuple((r.trace, bool(r.acceptable)) for r in state.learning_records)


def learning_verdicts(state: SessionState) -> Verdicts:
    """The session's learning data as (trace, acceptable, is_verdict): is_verdict is False for demonstrations."""
    return tuple((r.trace, bool(r.acceptable), r.kind == "query") for r in state.learning_records)


def belief(state: SessionState) -> Belief:
    """The learner's belief after the session's demonstrations and assessed queries."""
    c = state.config
    if c.flip_rate == 0.0:
        return belief_after(c.task, c.prior, learning_data(state))
    return noisy_belief_after(c.task, c.prior, c.flip_rate, learning_verdicts(state))


def beliefs_by_step(state: SessionState) -> list[Belief]:
    """The belief before any data and after each learning record, in order."""
    c = state.config
    data = learning_verdicts(state)
    return [noisy_belief_after(c.task, c.prior, c.flip_rate, data[:k]) for k in range(len(data) + 1)]


def position(state: SessionState) -> tuple[StepKind, int, int]:
    """Where a session is, without planning the robot's turn: (phase, index within it, phase total)."""
    c = state.config
    kind = state.phase
    totals = {
        "practice": c.n_practice,
        "demonstration": c.demonstrations_needed,
        "query": c.queries_needed,
        "test": c.n_tests,
        "done": 0,
    }
    return kind, (state.count(kind) if kind != "done" else 0), totals[kind]


@lru_cache(maxsize=4096)  # states are immutable values: the server asks for the same step several times
def next_step(state: SessionState) -> Step:
    """What happens next; robot turns come with the robot's execution (deterministic per seed)."""
    c = state.config
    kind, index, total = position(state)
    # Through the learner seam: the enumerating learner up to five objects (as before), the exact one past five.
    if kind == "query":
        strategy = "active" if c.protocol == "active" else "random"
        execution, p = robot_query(c.task, c.prior, c.flip_rate, learning_verdicts(state), strategy,
                                   _rng(c, kind, index))
        return Step(kind, index, total, execution, p)
    if kind == "test":
        execution, p = robot_plan(c.task, c.prior, c.flip_rate, learning_verdicts(state), c.criterion,
                                  _rng(c, kind, index))
        return Step(kind, index, total, execution, p)
    return Step(kind, index, total)


def observe(
    state: SessionState, kind: StepKind, trace: Trace | list[list[str]], acceptable: bool | None = None
) -> SessionState:
    """Record one execution of the expected kind; ProtocolError if it is not what comes next."""
    expected = state.phase
    if kind != expected:
        raise ProtocolError(f"cannot record a {kind} now: the session expects a {expected}")
    domain = get_domain(state.config.task)
    domain.check_trace(list(trace))
    frozen: Trace = tuple(frozenset(s) for s in trace)
    proposed: tuple[str, ...] | None = None
    if kind == "query":
        if not isinstance(acceptable, bool):
            raise ProtocolError(f"a query needs an assessment true or false, got {acceptable!r}")
        proposed = next_step(state).robot_execution.events  # type: ignore[union-attr]
    elif kind == "test":
        if acceptable is not None and not isinstance(acceptable, bool):
            raise ProtocolError(f"a test verdict must be true, false or absent, got {acceptable!r}")
        proposed = next_step(state).robot_execution.events  # type: ignore[union-attr]
    elif acceptable not in (None, True):
        raise ProtocolError(f"a {kind} is acceptable by definition; got acceptable={acceptable!r}")
    if kind == "demonstration":
        acceptable = True
    return replace(state, records=state.records + (Record(kind, frozen, acceptable, proposed),))
