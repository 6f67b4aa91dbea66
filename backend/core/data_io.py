"""Reading labelled executions: the project's JSON format and the paper authors' files.

Project format: ``{"executions": [{"trace": [[], ["dinner_plate"], ...], "label": true}, ...]}``;
a trace is the list of states, each the list of propositions true in it, initial state first.
Authors' files (dinner objects named W0..W4): ``demo_*.txt`` (one 0/1 row per state),
``demo_*.json`` (WaypointPredicates per object and time), ``query_*_trace.json`` (trace_slices),
and ``dist_*.json`` / ``batch_posterior.json`` posteriors in nested prefix-list form.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

from .belief import LabelledExecution
from .clauses import ClauseSpace
from .domain import Domain


class InputError(ValueError):
    """Input data that is malformed; the message names the file, the place and the problem."""


def parse_executions(data: Any, domain: Domain, source: str = "input") -> list[LabelledExecution]:
    """Validate and convert the project's executions JSON (already decoded)."""
    if not isinstance(data, dict) or not isinstance(data.get("executions"), list):
        raise InputError(f"{source}: expected an object with a list 'executions'")
    out = []
    known = set(domain.propositions)
    for i, item in enumerate(data["executions"]):
        where = f"{source}: executions[{i}]"
        if not isinstance(item, dict):
            raise InputError(f"{where}: expected an object with 'trace' and 'label'")
        trace, label = item.get("trace"), item.get("label")
        if not isinstance(label, bool):
            raise InputError(f"{where}.label: expected true or false, got {label!r}")
        if not isinstance(trace, list) or not trace:
            raise InputError(f"{where}.trace: expected a non-empty list of states (initial state first)")
        for t, state in enumerate(trace):
            if not isinstance(state, list) or not all(isinstance(p, str) for p in state):
                raise InputError(f"{where}.trace[{t}]: expected a list of proposition names, got {state!r}")
            unknown = set(state) - known
            if unknown:
                raise InputError(
                    f"{where}.trace[{t}]: unknown proposition(s) {', '.join(sorted(unknown))}; "
                    f"expected some of {', '.join(domain.propositions)}"
                )
        out.append(LabelledExecution.of(trace, label))
    return out


def load_executions(path: str | Path, domain: Domain) -> list[LabelledExecution]:
    """Read an executions JSON file."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    return parse_executions(data, domain, str(path))


# ---------------------------------------------------------------- the authors' formats


def _authors_names(domain: Domain) -> list[str]:
    return list(domain.propositions)


def persistent_trace(rows: Sequence[Sequence[bool]], domain: Domain) -> list[frozenset[str]]:
    """A trace from per-time 0/1 rows: a proposition holds from its first 1 on; empty initial state prepended."""
    names = _authors_names(domain)
    trace: list[frozenset[str]] = []
    seen: set[str] = set()
    for row in rows:
        if len(row) != len(names):
            raise InputError(f"a state row has {len(row)} values; expected {len(names)} (W0..W{len(names) - 1})")
        seen |= {names[i] for i, v in enumerate(row) if v}
        trace.append(frozenset(seen))
    if not trace or trace[0]:
        trace.insert(0, frozenset())
    return trace


def load_authors_demo(path: str | Path, domain: Domain) -> LabelledExecution:
    """Read one of the authors' demonstration files (.txt rows or .json WaypointPredicates)."""
    path = Path(path)
    try:
        if path.suffix == ".txt":
            rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
            return LabelledExecution.of(persistent_trace(rows, domain), True)
        data = json.loads(path.read_text())
        if "trace_slices" in data:
            return load_authors_query(path, domain, acceptable=bool(data.get("inferred_label", False)))
        per_object = data["Data"]["WaypointPredicates"]
        rows = [list(column) for column in zip(*per_object, strict=True)]
        return LabelledExecution.of(persistent_trace(rows, domain), bool(data.get("Label", True)))
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: not an authors' demonstration file ({exc})") from None


def load_authors_query(path: str | Path, domain: Domain, acceptable: bool) -> LabelledExecution:
    """Read one of the authors' query traces (trace_slices) with the given assessment."""
    path = Path(path)
    data = json.loads(Path(path).read_text())
    names = _authors_names(domain)
    rows = [[bool(s[f"W{i}"]) for i in range(len(names))] for s in data["trace_slices"]]
    return LabelledExecution.of(persistent_trace(rows, domain), acceptable)


def authors_formula_mask(node: Any, space: ClauseSpace, names: Sequence[str]) -> int:
    """Mask of an authors' nested prefix formula (imp P_i guards dropped, W_i renamed)."""
    if not isinstance(node, list) or not node:
        raise InputError(f"not a formula node: {node!r}")
    op = node[0]
    if op == "true" and len(node) == 1:
        return 0  # the empty conjunction
    if op == "and":
        mask = 0
        for part in node[1:]:
            mask |= authors_formula_mask(part, space, names)
        return mask
    if op == "imp":
        return authors_formula_mask(node[2], space, names)
    if op == "G" and node[1][0] == "not":
        return space.g_bit(_name(node[1][1], names))
    if op == "F":
        return space.f_bit(_name(node[1], names))
    if op == "U" and node[1][0] == "not":
        return space.before_bit(_name(node[2], names), _name(node[1][1], names))
    raise InputError(f"not a template clause: {node!r}")


def _name(atom: Any, names: Sequence[str]) -> str:
    if not (isinstance(atom, list) and len(atom) == 1 and str(atom[0]).startswith("W")):
        raise InputError(f"expected a W_i atom, got {atom!r}")
    return names[int(atom[0][1:])]


def load_authors_posterior(path: str | Path, domain: Domain) -> dict[int, float]:
    """An authors' posterior as {clause-set mask: probability}, duplicates merged."""
    data = json.loads(Path(path).read_text())
    names = _authors_names(domain)
    out: dict[int, float] = {}
    for formula, p in zip(data["support"], data["probs"], strict=True):
        mask = authors_formula_mask(formula, domain.clause_space, names)
        out[mask] = out.get(mask, 0.0) + float(p)
    return out
