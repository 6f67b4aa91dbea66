"""CSV cells that a spreadsheet would run as formulas are escaped; everything else is left alone."""

from __future__ import annotations

import csv
import io

from hypothesis import given
from hypothesis import strategies as st

from tableteach.web.exports import FORMULA_STARTS, cell, csv_lines


def test_formula_like_cells_get_an_apostrophe() -> None:
    assert [cell(v) for v in ["=1+1", "+1", "-2", "@SUM(A1)", "\tx", "\rx"]] == [
        "'=1+1", "'+1", "'-2", "'@SUM(A1)", "'\tx", "'\rx"]
    assert [cell(v) for v in ["F(bowl)", "(!bowl U knife)", -2, 0.5, None, True, False]] == [
        "F(bowl)", "(!bowl U knife)", -2, 0.5, None, "true", "false"]


@given(st.lists(st.lists(st.text(max_size=12), min_size=1, max_size=4), min_size=1, max_size=6))
def test_round_trip_keeps_values_and_no_cell_starts_like_a_formula(rows: list[list[str]]) -> None:
    text = "".join(csv_lines(rows))
    back = list(csv.reader(io.StringIO(text, newline="")))
    assert len(back) == len(rows)
    for got_row, row in zip(back, rows, strict=True):
        for got, value in zip(got_row, row, strict=True):
            assert not got.startswith(FORMULA_STARTS)
            assert got == ("'" + value if value.startswith(FORMULA_STARTS) else value)
