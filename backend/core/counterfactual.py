"""Counterfactual learners: a session's recorded demonstrations and verdicts run again through another
learner configuration (another prior, the noise-aware likelihood, the demonstrations only).

A learner spec is ``study`` (the study's own prior and flip rate) or comma-separated settings ``prior=NAME``,
``flip=P`` (the noise-aware learner, P in [0, 0.5); ``flip=0`` is the authors' learner) and
``data=all|demonstrations`` (``demonstrations``: Batch learning from the same session). Unset settings are the
study's. The recorded queries stay what they were: another learner changes what is learned from the data, not
which executions were shown.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator, Sequence

from .belief import Belief, check_flip_rate
from .domain import get_domain
from .learner_seam import belief_after, check_exact, path_of
from .priors import NAMED_PRIORS
from .session import Verdicts, noisy_belief_after

DATA_CHOICES = ("all", "demonstrations")
SETTINGS = ("prior", "flip", "data")


@dataclass(frozen=True)
class LearnerSpec:
    """One learner configuration: its name as given, prior and flip rate (None: the study's), data used."""

    name: str
    prior: str | None = None
    flip_rate: float | None = None
    data: str = "all"

    @staticmethod
    def parse(text: str) -> "LearnerSpec":
        """Parse ``study`` or ``prior=NAME,flip=P,data=all|demonstrations``; ValueError names what is wrong."""
        text = text.strip()
        if text == "study":
            return LearnerSpec("study")
        fields: dict[str, Any] = {}
        for part in text.split(","):
            key, eq, value = (s.strip() for s in part.partition("="))
            if not eq or key not in SETTINGS or key in fields:
                raise ValueError(f"unknown learner {text!r}: {part!r} is not a setting; expected 'study' or "
                                 "settings prior=NAME, flip=P, data=all|demonstrations separated by commas")
            fields[key] = value
        if "prior" in fields and fields["prior"] not in NAMED_PRIORS:
            raise ValueError(f"unknown learner {text!r}: prior {fields['prior']!r}; expected one of "
                             f"{', '.join(NAMED_PRIORS)}")
        if "data" in fields and fields["data"] not in DATA_CHOICES:
            raise ValueError(f"unknown learner {text!r}: data {fields['data']!r}; expected one of "
                             f"{', '.join(DATA_CHOICES)}")
        flip = None
        if "flip" in fields:
            try:
                flip = float(fields["flip"])
            except ValueError:
                raise ValueError(f"unknown learner {text!r}: flip {fields['flip']!r} is not a number") from None
            check_flip_rate(flip, f"learner {text!r}: flip")
        return LearnerSpec(text, fields.get("prior"), flip, fields.get("data", "all"))

    def resolved(self, study_prior: str, study_flip_rate: float) -> tuple[str, float]:
        """(prior, flip rate) of this learner in a study with these settings."""
        return (self.prior or study_prior, study_flip_rate if self.flip_rate is None else self.flip_rate)


def spec_pattern() -> str:
    """A regular expression of learner specs in the canonical order (prior, flip, data), each setting at most once;
    ``LearnerSpec.parse`` also takes them in any order and flip rates written otherwise (.1, 1e-2)."""
    prior = "prior=(?:" + "|".join(NAMED_PRIORS) + ")"  # names of letters, digits and -
    flip = r"flip=0(?:\.[0-4][0-9]{0,8})?"
    data = "data=(?:" + "|".join(DATA_CHOICES) + ")"
    return f"^(?:study|{prior}(?:,{flip})?(?:,{data})?|{flip}(?:,{data})?|{data})$"


def parse_learners(texts: Sequence[str]) -> list[LearnerSpec]:
    """Learner specs, each given once; ValueError names a bad or repeated one."""
    learners = [LearnerSpec.parse(text) for text in texts]
    names = [learner.name for learner in learners]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"learner given twice: {', '.join(repeated)}")
    return learners


def beliefs_by_step(learner: LearnerSpec, data: Verdicts, *, task: str, study_prior: str,
                    study_flip_rate: float = 0.0) -> Iterator[Belief]:
    """The learner's belief before any data and after each recorded item (a demonstrations-only learner keeps
    its belief through a verdict)."""
    prior, flip = learner.resolved(study_prior, study_flip_rate)
    for step in range(len(data) + 1):
        seen = tuple(d for d in data[:step] if learner.data == "all" or not d[2])
        yield noisy_belief_after(task, prior, flip, seen)


def step_views(learner: LearnerSpec, data: Verdicts, truth_mask: int | None, *, task: str, study_prior: str,
               study_flip_rate: float = 0.0) -> list[dict[str, Any]]:
    """Per step (0: the prior): the learner's similarity to the truth (None if unknown), entropy, MAP formula,
    asked through the learner seam (past five objects the exact learner's; ValueError names a setting it does not
    offer, e.g. a flip rate)."""
    space = get_domain(task).clause_space
    prior, flip = learner.resolved(study_prior, study_flip_rate)
    if path_of(task) == "exact":
        check_exact(prior, flip)
    out = []
    for step in range(len(data) + 1):
        seen = tuple(d for d in data[:step] if learner.data == "all" or not d[2])
        belief = belief_after(task, prior, flip, seen)
        out.append({"step": step, "similarity": None if truth_mask is None else belief.similarity(truth_mask),
                    "entropy": belief.entropy + 0.0, "map_formula": space.text_of(belief.map_mask)})
    return out
