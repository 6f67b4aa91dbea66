"""The standard HRI questionnaires (services.instruments): published item counts and scoring rules."""

from __future__ import annotations

import pytest

from tableteach.services.instruments import INSTRUMENTS, instrument_items, scores


def _answer(name: str, values: list[int]) -> tuple[list[dict], dict[str, int]]:
    items = instrument_items(name)
    return items, {item["id"]: v for item, v in zip(items, values, strict=True)}


def test_each_instrument_has_its_published_number_of_items_and_a_citation() -> None:
    assert {name: len(i.items) for name, i in INSTRUMENTS.items()} == {"sus": 10, "tlx": 6, "godspeed": 24,
                                                                        "trust": 12}
    assert all(i.citation and "(" in i.citation for i in INSTRUMENTS.values())


def test_sus_scores_odd_items_up_and_even_items_down_times_two_and_a_half() -> None:
    assert scores(*_answer("sus", [5, 1] * 5)) == [("sus", "sus", 100.0, 10)]
    assert scores(*_answer("sus", [1, 5] * 5)) == [("sus", "sus", 0.0, 10)]
    # Brooke's worked rule on a mixed answer: (4-1)+(5-2)+(3-1)+(5-1)+(4-1)+(5-2)+(5-1)+(5-1)+(4-1)+(5-3) = 31
    assert scores(*_answer("sus", [4, 2, 3, 1, 4, 2, 5, 1, 4, 3]))[0][2] == pytest.approx(77.5)


def test_raw_tlx_is_the_mean_of_the_six_ratings_and_a_missing_answer_leaves_no_score() -> None:
    items, answers = _answer("tlx", [50, 20, 70, 30, 60, 10])
    got = {scale: score for _i, scale, score, _n in scores(items, answers)}
    assert got["raw_tlx"] == pytest.approx(40.0) and got["performance"] == 30
    del answers["tlx_effort"]
    assert "raw_tlx" not in {scale for _i, scale, _s, _n in scores(items, answers)}


def test_godspeed_series_and_the_trust_factors_are_means_of_their_items() -> None:
    got = {scale: (score, n) for _i, scale, score, n in scores(*_answer("godspeed", [1] * 5 + [2] * 6 + [3] * 5
                                                                          + [4] * 5 + [5] * 3))}
    assert got == {"anthropomorphism": (1.0, 5), "animacy": (2.0, 6), "likeability": (3.0, 5),
                   "intelligence": (4.0, 5), "safety": (5.0, 3)}
    got = {scale: score for _i, scale, score, _n in scores(*_answer("trust", [2] * 5 + [6] * 7))}
    assert got == {"distrust": 2.0, "trust": 6.0}
