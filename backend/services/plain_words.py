"""Validation errors in plain words: what was wrong with a field and what was expected, never Python's spelling
(no "None", "True" or "Input should be")."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, get_args

from pydantic import BaseModel


def shown(value: Any) -> str:
    """A value as a person would write it: nothing, true/false, a number, "text" (shortened)."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return f"{value:g}" if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return f'"{value[:60]}…"' if len(value) > 60 else f'"{value}"'
    if isinstance(value, list):
        return "a list" if value else "an empty list"
    if isinstance(value, dict):
        return "an object" if value else "an empty object"
    return "a value of another kind"


def _options(expected: str) -> str:
    """Pydantic's "'a', 'b' or 'c'" as "a, b or c"."""
    return expected.replace("'", "")


def _bounds(ctx: Mapping[str, Any]) -> str:
    low, high = ctx.get("ge", ctx.get("gt")), ctx.get("le", ctx.get("lt"))
    if low is not None and high is not None:
        return f"from {low:g} to {high:g}"
    if "gt" in ctx:
        return f"above {low:g}"
    if "lt" in ctx:
        return f"below {high:g}"
    if low is not None:
        return f"of at least {low:g}"
    return f"of at most {high:g}"


def plain_message(error: Mapping[str, Any], hints: Mapping[str, str] | None = None,
                  ranges: Mapping[str, tuple[float, float]] | None = None) -> str:
    """One pydantic error dict as a plain sentence; hints (field path -> expected) say what a pattern means and
    ranges (field path -> (low, high)) a number's bounds."""
    kind = error.get("type", "")
    ctx = error.get("ctx") or {}
    value = error.get("input")
    got = f", got {shown(value)}"
    where = ".".join(str(part) for part in error.get("loc", ()) if part != "body")
    if kind == "missing":
        return "is required"
    if kind == "extra_forbidden":
        return "is not a field here (check its spelling)"
    if kind == "literal_error":
        return f"is {shown(value)}; expected one of {_options(str(ctx.get('expected', '')))}"
    span = (ranges or {}).get(_generic(where))
    bounds = f" from {span[0]:g} to {span[1]:g}" if span else ""
    if kind in ("int_type", "int_parsing", "int_from_float"):
        return f"must be a whole number{bounds}{got}"
    if kind in ("float_type", "float_parsing"):
        return f"must be a number{bounds}{got}"
    if kind in ("greater_than_equal", "less_than_equal", "greater_than", "less_than"):
        return f"must be a number{bounds or ' ' + _bounds(ctx)}{got}"
    if kind in ("bool_type", "bool_parsing"):
        return f"must be true or false{got}"
    if kind in ("string_type",):
        return f"must be text{got}"
    if kind == "string_too_short":
        return "must not be empty" if ctx.get("min_length") == 1 else f"needs at least {ctx['min_length']} characters"
    if kind == "string_too_long":
        return f"must be at most {ctx.get('max_length')} characters long"
    if kind == "string_pattern_mismatch":
        hint = (hints or {}).get(_generic(where), "")
        return f"must be {hint}{got}" if hint else f"is not in the expected form{got}"
    if kind == "list_type":
        return f"must be a list{got}"
    if kind == "too_short":
        return f"needs at least {ctx.get('min_length')} entries"
    if kind == "too_long":
        return f"may have at most {ctx.get('max_length')} entries"
    if kind in ("dict_type", "model_type", "model_attributes_type"):
        return f"must be an object with named fields{got}"
    if kind == "value_error":
        return str(ctx.get("error", error.get("msg", "is not acceptable")))
    if kind == "json_invalid":
        return "is not valid JSON"
    return str(error.get("msg", "is not acceptable")).replace("Input should be", "should be")


def _generic(where: str) -> str:
    """A field path with list positions as *, e.g. tasks.0.key -> tasks.*.key (how hints are keyed)."""
    return ".".join("*" if part.isdigit() else part for part in where.split("."))


def field_errors(errors: Iterable[Mapping[str, Any]], hints: Mapping[str, str] | None = None,
                 ranges: Mapping[str, tuple[float, float]] | None = None) -> list[dict[str, str]]:
    """Pydantic errors as [{field, message}] in plain words, one per field (the first error of each)."""
    out: dict[str, str] = {}
    for error in errors:
        loc = [str(part) for part in error.get("loc", ()) if part != "body"]
        if error.get("type") in ("union_tag_invalid",) or (loc and loc[-1] in ("int", "str", "none", "bool")):
            loc = loc[:-1]  # a union's member name is no field of the request
        field = ".".join(loc) or "body"
        out.setdefault(field, plain_message(error, hints, ranges))
    return [{"field": field, "message": message} for field, message in out.items()]


def number_ranges(model: type[BaseModel], prefix: str = "") -> dict[str, tuple[float, float]]:
    """Every bounded number field of a model and its nested models (lists as *): path -> (low, high)."""
    out: dict[str, tuple[float, float]] = {}
    for name, field in model.model_fields.items():
        path = f"{prefix}{name}"
        low = next((m.ge for m in field.metadata if getattr(m, "ge", None) is not None), None)
        high = next((m.le for m in field.metadata if getattr(m, "le", None) is not None), None)
        if low is not None and high is not None:
            out[path] = (float(low), float(high))
        for arg in get_args(field.annotation) or (field.annotation,):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                out.update(number_ranges(arg, f"{path}.*."))
    return out
