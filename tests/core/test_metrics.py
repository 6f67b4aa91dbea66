"""The similarity metrics: the authors' IoU (their recorded checks) and the strict variant."""

import numpy as np
import pytest

from tableteach.core.domain import DINNER_TASK_FORMULAS, get_domain
from tableteach.core.hypotheses import get_space
from tableteach.core.metrics import expanded_masks, similarities, similarity

DINNER = get_domain("dinner").clause_space
TASK1 = DINNER.mask_of_formula(DINNER_TASK_FORMULAS["task1"])
TASK2 = DINNER.mask_of_formula(DINNER_TASK_FORMULAS["task2"])
LAB_2021 = DINNER.mask_of_formula("G(!small_plate) & F(dinner_plate) & F(bowl) & (!small_plate U bowl)"
                                  " & (!bowl U dinner_plate) & (!small_plate U dinner_plate)")


def test_the_authors_recorded_checks():
    assert similarity(DINNER, TASK1, TASK2) == pytest.approx(1 / 3)
    assert similarity(DINNER, TASK2, LAB_2021) == 1.0
    # an order whose *earlier* item is forbidden: the authors keep (a, b) and 'a'; strict drops both
    odd = DINNER.mask_of_formula("G(!small_plate) & F(bowl) & (!bowl U small_plate)")
    plain = DINNER.mask_of_formula("G(!small_plate) & F(bowl)")
    assert similarity(DINNER, odd, plain) == pytest.approx(2 / 4)
    assert similarity(DINNER, odd, plain, "strict") == 1.0


def test_the_metrics_agree_on_the_synthetic_domain_and_differ_on_the_dinner_table():
    synthetic = get_space("synthetic", "chains-2020-sat")
    assert np.array_equal(expanded_masks(synthetic, "authors"), expanded_masks(synthetic, "strict"))
    dinner = get_space("dinner", "chains-2020-sat")
    authors, strict = similarities(dinner, TASK2), similarities(dinner, TASK2, "strict")
    assert not np.array_equal(authors, strict) and np.all((authors >= 0) & (authors <= 1))


def test_an_unknown_metric_is_refused():
    with pytest.raises(ValueError, match="unknown similarity metric 'jaccard'; expected one of authors, strict"):
        similarity(DINNER, TASK1, TASK2, "jaccard")
