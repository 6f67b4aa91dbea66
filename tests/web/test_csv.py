"""CSV cells that a spreadsheet would run as formulas are escaped; everything else is left alone."""

from __future__ import annotations

import csv
import io

from hypothesis import given
from hypothesis import strategies as st

from tableteach.web.exports import FORMULA_STARTS, cell, csv_lines, needs_escape


def test_formula_like_cells_get_an_apostrophe() -> None:
    assert [cell(v) for v in ["=1+1", "+1", "-2", "@SUM(A1)", "\tx", "\rx"]] == [
        "'=1+1", "'+1", "'-2", "'@SUM(A1)", "'\tx", "'\rx"]
    assert [cell(v) for v in [" =1+1", "\n=1+1", "\uff1d1+1", "\u3000\uff0bA1", "  @x", "\tx"]] == [
        "' =1+1", "'\n=1+1", "'\uff1d1+1", "'\u3000\uff0bA1", "'  @x", "'\tx"]
    assert [cell(v) for v in ["F(bowl)", "(!bowl U knife)", -2, 0.5, None, True, False]] == [
        "F(bowl)", "(!bowl U knife)", -2, 0.5, None, "true", "false"]


@given(st.lists(st.lists(st.text(max_size=12), min_size=1, max_size=4), min_size=1, max_size=6))
def test_round_trip_keeps_values_and_no_cell_starts_like_a_formula(rows: list[list[str]]) -> None:
    text = "".join(csv_lines(rows))
    back = list(csv.reader(io.StringIO(text, newline="")))
    assert len(back) == len(rows)
    for got_row, row in zip(back, rows, strict=True):
        for got, value in zip(got_row, row, strict=True):
            assert not got.lstrip().startswith(FORMULA_STARTS) and not got[:1].isspace()
            assert got == ("'" + value if needs_escape(value) else value)
