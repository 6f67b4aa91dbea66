"""Learner specs for replays and the dashboard's what-if: parsing, the schema's pattern, the study's settings."""

import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tableteach.core.counterfactual import LearnerSpec, beliefs_by_step, parse_learners, spec_pattern
from tableteach.core.session import noisy_belief_after


@settings(max_examples=200, deadline=None)
@given(st.from_regex(spec_pattern(), fullmatch=True))
def test_every_spec_the_pattern_allows_is_accepted(text):
    spec = LearnerSpec.parse(text)
    assert spec.name == text and spec.data in ("all", "demonstrations")


def test_settings_left_out_are_the_study_s():
    assert LearnerSpec.parse("study").resolved("chains-2020", 0.2) == ("chains-2020", 0.2)
    assert LearnerSpec.parse("flip=0").resolved("chains-2020", 0.2) == ("chains-2020", 0.0)
    assert LearnerSpec.parse("data=demonstrations,prior=forest").resolved("chains-2020", 0.1) == ("forest", 0.1)
    assert not re.match(spec_pattern(), "data=demonstrations,prior=forest")  # the schema names one order only


@pytest.mark.parametrize("texts, message", [
    (["flips=0.1"], "unknown learner 'flips=0.1': 'flips=0.1' is not a setting"),
    (["flip=0.5"], "flip must be a probability in [0, 0.5), got 0.5"),
    (["flip=x"], "flip 'x' is not a number"),
    (["prior=flat"], "prior 'flat'; expected one of"),
    (["data=some"], "data 'some'; expected one of all, demonstrations"),
    (["flip=0.1,flip=0.2"], "'flip=0.2' is not a setting"),
    (["flip=0.1", "flip=0.1"], "learner given twice: flip=0.1"),
])
def test_bad_specs_say_what_is_wrong(texts, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_learners(texts)


def test_a_demonstrations_only_learner_keeps_its_belief_through_a_verdict():
    demo = (frozenset(), frozenset({"bowl"}))
    query = (frozenset(), frozenset({"fork"}))
    data = ((demo, True, False), (query, False, True))
    study = list(beliefs_by_step(LearnerSpec.parse("study"), data, task="dinner", study_prior="chains-2020-sat"))
    demos = list(beliefs_by_step(LearnerSpec.parse("data=demonstrations"), data, task="dinner",
                                 study_prior="chains-2020-sat"))
    assert study[1] is demos[1] and demos[2] is demos[1] and study[2] is not demos[2]
    noisy = list(beliefs_by_step(LearnerSpec.parse("study"), data, task="dinner", study_prior="chains-2020-sat",
                                 study_flip_rate=0.2))
    assert noisy[2] is noisy_belief_after("dinner", "chains-2020-sat", 0.2, data)
