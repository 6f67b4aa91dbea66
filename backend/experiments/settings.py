"""The settings of a simulation sweep: what the paper's experiment varies, validated up front."""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from typing import Any

from ..core.belief import check_flip_rate
from ..core.domain import DINNER_TASK_FORMULAS
from ..core.priors import DEFAULT_PRIOR, NAMED_PRIORS
from ..core.metrics import DEFAULT_METRIC, SIMILARITY_METRICS
from ..core.queries import ACTIVE_STRATEGIES, DEFAULT_ACTIVE_STRATEGY, DEFAULT_QUERY_TIES, QUERY_TIES
from ..core.teachers import DEFAULT_DEMO_MODE, DEMO_MODES

N_DEMONSTRATIONS = 2  # the paper's protocols all start from two demonstrations

# Experiment domain -> (core task, fixed ground truth or None for a random one per run).
DOMAINS: dict[str, tuple[str, str | None]] = {
    "synthetic": ("synthetic", None),
    "dinner-task1": ("dinner", DINNER_TASK_FORMULAS["task1"]),
    "dinner-task2": ("dinner", DINNER_TASK_FORMULAS["task2"]),
    "dinner-random": ("dinner", None),
}
TRUTH_SAMPLERS = ("prior", "authors")
FIXED_TRUTH = "fixed"
DEFAULT_N_QUERY = (1, 2, 3, 4, 5, 6)
# The synthetic domain's size; configs written before these settings existed had the paper's 5 + 5.
SIZE_DEFAULTS = {"n_waypoints": 5, "n_threats": 5}
MAX_ENUMERATED_WAYPOINTS = 5  # past this, or past MAX_ENUMERATED_HYPOTHESES, the exact learner runs the sweep
MAX_ENUMERATED_HYPOTHESES = 1_100_000
MAX_EXACT_WAYPOINTS, MAX_EXACT_THREATS = 10, 10
# sets of linear chains over n orderable propositions
CHAIN_STRUCTURES = {2: 3, 3: 13, 4: 73, 5: 501, 6: 4051, 7: 37633, 8: 394353, 9: 4596553, 10: 58941091}


@dataclass(frozen=True)
class ExperimentSettings:
    """Everything that determines a sweep's numbers (not how or where it runs)."""

    domain: str = "synthetic"
    runs: int = 200
    n_query: tuple[int, ...] = DEFAULT_N_QUERY
    seed: int = 0
    prior: str = DEFAULT_PRIOR
    truth_sampler: str = "prior"
    demo_mode: str = DEFAULT_DEMO_MODE
    noise: float = 0.0
    learner_flip_rate: float = 0.0
    similarity: str = DEFAULT_METRIC
    query_ties: str = DEFAULT_QUERY_TIES
    active_strategy: str = DEFAULT_ACTIVE_STRATEGY
    test_success: bool = False
    n_demonstrations: int = field(default=N_DEMONSTRATIONS)
    n_waypoints: int = SIZE_DEFAULTS["n_waypoints"]
    n_threats: int = SIZE_DEFAULTS["n_threats"]

    def __post_init__(self) -> None:
        if self.domain not in DOMAINS:
            raise ValueError(f"unknown domain {self.domain!r}; expected one of {', '.join(DOMAINS)}")
        _whole("runs", self.runs, minimum=1)
        _whole("seed", self.seed, minimum=0)
        _whole("n_demonstrations", self.n_demonstrations, minimum=0)
        if not self.n_query:
            raise ValueError("n_query needs at least one value, e.g. 1,2,3")
        for n in self.n_query:
            _whole("n_query", n, minimum=0)
        if list(self.n_query) != sorted(set(self.n_query)):
            raise ValueError(f"n_query values must be distinct and increasing, got {list(self.n_query)}")
        if self.prior not in NAMED_PRIORS:
            raise ValueError(f"unknown prior {self.prior!r}; expected one of {', '.join(NAMED_PRIORS)}")
        fixed = DOMAINS[self.domain][1] is not None
        allowed = (FIXED_TRUTH,) if fixed else TRUTH_SAMPLERS
        if self.truth_sampler not in allowed:
            why = f"domain {self.domain!r} has a fixed ground truth" if fixed else "ground truths are drawn per run"
            raise ValueError(
                f"truth sampler {self.truth_sampler!r} does not apply: {why}; expected one of {', '.join(allowed)}"
            )
        if self.demo_mode not in DEMO_MODES:
            raise ValueError(f"unknown demonstration mode {self.demo_mode!r}; expected one of {', '.join(DEMO_MODES)}")
        if self.similarity not in SIMILARITY_METRICS:
            raise ValueError(
                f"unknown similarity metric {self.similarity!r}; expected one of {', '.join(SIMILARITY_METRICS)}"
            )
        if self.query_ties not in QUERY_TIES:
            raise ValueError(f"unknown query tie-breaking {self.query_ties!r}; expected one of {', '.join(QUERY_TIES)}")
        self._check_size()
        if self.active_strategy not in ACTIVE_STRATEGIES:
            raise ValueError(f"unknown active query strategy {self.active_strategy!r}; "
                             f"expected one of {', '.join(ACTIVE_STRATEGIES)}")
        if not isinstance(self.test_success, bool):
            raise ValueError(f"test_success must be true or false, got {self.test_success!r}")
        if isinstance(self.noise, bool) or not isinstance(self.noise, (int, float)) or not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be a probability in [0, 1], got {self.noise!r}")
        check_flip_rate(self.learner_flip_rate, "learner_flip_rate")

    def _check_size(self) -> None:
        """The synthetic domain's size: 2 to 10 waypoints; the exact learner past the enumerable spaces."""
        _whole("n_waypoints", self.n_waypoints, minimum=2)
        _whole("n_threats", self.n_threats, minimum=0)
        if self.domain != "synthetic" and (self.n_waypoints, self.n_threats) != tuple(SIZE_DEFAULTS.values()):
            raise ValueError(f"--n-waypoints and --n-threats size the synthetic domain; domain {self.domain!r} "
                             "has its own objects")
        if self.exact_learner:
            self._check_exact()

    @property
    def exact_learner(self) -> bool:
        """Whether the sweep runs the exact factorised learner (a synthetic domain past enumeration)."""
        return self.domain == "synthetic" and (
            self.n_waypoints > MAX_ENUMERATED_WAYPOINTS or self._space_size(self.n_threats) > MAX_ENUMERATED_HYPOTHESES)

    def _check_exact(self) -> None:
        """Raise ValueError naming what the exact learner's sweep does not offer."""
        from ..core.priors import get_prior

        if self.n_waypoints > MAX_EXACT_WAYPOINTS:
            raise ValueError(f"n_waypoints {self.n_waypoints}: the exact learner takes 2 to {MAX_EXACT_WAYPOINTS}")
        if self.n_threats > MAX_EXACT_THREATS:
            raise ValueError(f"n_threats {self.n_threats}: expected at most {MAX_EXACT_THREATS}")
        structure = get_prior(self.prior).structure
        wrong = [(name, value, want) for name, value, want in (
            ("prior structure", structure, "chains' or 'total-order"),
            ("similarity", self.similarity, "authors"),
            ("active_strategy", self.active_strategy, "uncertainty"),
            ("demo_mode", self.demo_mode, "required-only"),
            ("truth_sampler", self.truth_sampler, "prior"),
            ("learner_flip_rate", self.learner_flip_rate, 0.0),
        ) if value != want and not (name == "prior structure" and value in ("chains", "total-order"))]
        if wrong:
            name, value, want = wrong[0]
            raise ValueError(
                f"{name} {value!r} is not offered past enumeration ({self.n_waypoints} waypoints, {self.n_threats} "
                f"threats), where the exact learner runs the sweep; expected {name} '{want}'")

    def _space_size(self, n_threats: int) -> int:
        """Chain structures times G/F codes: the enumerated space of the chains priors."""
        return CHAIN_STRUCTURES[self.n_waypoints] * 2 ** (self.n_waypoints + n_threats)


    @property
    def task(self) -> str:
        """The core task (domain of propositions) the experiment domain runs on."""
        return DOMAINS[self.domain][0]

    @property
    def fixed_truth(self) -> str | None:
        """The ground-truth formula of a fixed-truth domain, else None."""
        return DOMAINS[self.domain][1]

    @property
    def max_n_query(self) -> int:
        """The longest query sequence a run computes (shorter ones are its prefixes)."""
        return max(self.n_query)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready form (lists for tuples)."""
        data = asdict(self)
        data["n_query"] = list(self.n_query)
        return data

    @staticmethod
    def from_json(data: dict[str, Any]) -> "ExperimentSettings":
        """Rebuild from ``to_json`` output; ValueError names what is malformed."""
        try:
            return ExperimentSettings(**{**data, "n_query": tuple(data["n_query"])})
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed experiment settings {json.dumps(data)}: {exc}") from exc


def resolve_truth_sampler(domain: str, requested: str | None) -> str:
    """The truth sampler a domain uses: 'fixed' for the study tasks, else the request (default 'prior')."""
    if domain not in DOMAINS:
        raise ValueError(f"unknown domain {domain!r}; expected one of {', '.join(DOMAINS)}")
    if DOMAINS[domain][1] is not None:
        if requested not in (None, FIXED_TRUTH):
            raise ValueError(
                f"--truth-sampler {requested} does not apply to {domain}, whose ground truth is fixed; "
                "use synthetic or dinner-random to draw ground truths"
            )
        return FIXED_TRUTH
    return requested or "prior"


def parse_n_query(text: str) -> tuple[int, ...]:
    """Parse '1,2,3' or '1-6' (or a mix such as '0,2-4') into sorted distinct counts."""
    values: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        span = re.fullmatch(r"(\d+)-(\d+)", part)
        try:
            values.update(range(int(span[1]), int(span[2]) + 1) if span else [int(part)])
        except ValueError:
            raise ValueError(
                f"--n-query {text!r}: {part!r} is not a whole number; expected e.g. 1,2,3 or 1-6"
            ) from None
    negative = sorted(v for v in values if v < 0)
    if negative:
        raise ValueError(f"--n-query {text!r}: the number of queries must be >= 0, got {negative[0]}")
    return tuple(sorted(values))


def _whole(name: str, value: Any, *, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}, got {value!r}")
