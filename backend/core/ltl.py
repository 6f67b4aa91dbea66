"""Linear temporal logic on finite traces: syntax tree, parser and printer.

Text syntax (loosest binding first): ``a -> b`` (right-associative), ``a | b``, ``a & b``,
``a U b`` / ``a R b`` (right-associative), then the prefix operators ``!``, ``X``, ``WX``
(weak next), ``F``, ``G``, atoms (``true``, ``false``, proposition names) and parentheses.
Example: ``F(bowl) & (!bowl U dinner_plate) & G(!small_plate)``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterable, Union

KEYWORDS = frozenset({"X", "WX", "F", "G", "U", "R", "true", "false", "END"})


@dataclass(frozen=True)
class Const:
    """The constant true or false."""

    value: bool


@dataclass(frozen=True)
class Prop:
    """An atomic proposition, true in a state that contains its name."""

    name: str


@dataclass(frozen=True)
class End:
    """True exactly on the empty suffix after the last state (internal; made by progressing WX)."""


@dataclass(frozen=True)
class Not:
    """Negation."""

    arg: "Formula"


@dataclass(frozen=True)
class And:
    """Conjunction of two or more formulas."""

    args: tuple["Formula", ...]


@dataclass(frozen=True)
class Or:
    """Disjunction of two or more formulas."""

    args: tuple["Formula", ...]


@dataclass(frozen=True)
class Implies:
    """Implication ``left -> right``."""

    left: "Formula"
    right: "Formula"


@dataclass(frozen=True)
class Next:
    """Strong next: a next state exists and ``arg`` holds there."""

    arg: "Formula"


@dataclass(frozen=True)
class WeakNext:
    """Weak next: this is the last state, or ``arg`` holds in the next one."""

    arg: "Formula"


@dataclass(frozen=True)
class Eventually:
    """``F arg``: arg holds now or in some later state."""

    arg: "Formula"


@dataclass(frozen=True)
class Always:
    """``G arg``: arg holds now and in every later state."""

    arg: "Formula"


@dataclass(frozen=True)
class Until:
    """Strong until ``left U right``: right eventually holds, left holds until then."""

    left: "Formula"
    right: "Formula"


@dataclass(frozen=True)
class Release:
    """``left R right``: right holds until and including the first state where left holds."""

    left: "Formula"
    right: "Formula"


Formula = Union[Const, Prop, End, Not, And, Or, Implies, Next, WeakNext, Eventually, Always, Until, Release]
TRUE = Const(True)
FALSE = Const(False)


class ParseError(ValueError):
    """A formula's text could not be parsed; names the position and what was expected."""

    def __init__(self, text: str, position: int, expected: str, found: str) -> None:
        self.text = text
        self.position = position
        self.expected = expected
        self.found = found
        super().__init__(f"at position {position}: expected {expected}, found {found} in {text!r}")


class UnknownPropositionError(ValueError):
    """A formula names propositions that the task does not have."""

    def __init__(self, unknown: Iterable[str], known: Iterable[str]) -> None:
        self.unknown = sorted(set(unknown))
        self.known = sorted(known)
        super().__init__(
            f"unknown proposition(s) {', '.join(self.unknown)}; expected one of {', '.join(self.known)}"
        )


def conj(args: Iterable[Formula]) -> Formula:
    """Conjunction of the given formulas (true if none, the formula itself if one)."""
    items = tuple(args)
    if not items:
        return TRUE
    return items[0] if len(items) == 1 else And(items)


def disj(args: Iterable[Formula]) -> Formula:
    """Disjunction of the given formulas (false if none, the formula itself if one)."""
    items = tuple(args)
    if not items:
        return FALSE
    return items[0] if len(items) == 1 else Or(items)


# ---------------------------------------------------------------- parsing

_TOKEN = re.compile(r"\s*(?:(?P<op>->|[!&|()])|(?P<word>[A-Za-z_][A-Za-z0-9_]*)|(?P<bad>\S))")


def _tokenize(text: str) -> list[tuple[str, int]]:
    tokens: list[tuple[str, int]] = []
    pos = 0
    while pos < len(text):
        match = _TOKEN.match(text, pos)
        if match is None:  # only trailing whitespace is left
            break
        if match.group("bad") is not None:
            raise ParseError(text, match.start("bad"), "an operator, proposition or parenthesis",
                             repr(match.group("bad")))
        kind = "op" if match.group("op") is not None else "word"
        tokens.append((match.group(kind), match.start(kind)))
        pos = match.end()
    return tokens


MAX_DEPTH = 100  # nested operators; template formulas nest 3-4 deep, a study's rarely beyond 10
# Operators and parentheses open at once while parsing: a formula within MAX_DEPTH written out by to_text opens at
# most a parenthesis and an operator per level, so its own text always parses again.
MAX_PENDING = 2 * MAX_DEPTH + 2

_UNARY = {"!": Not, "X": Next, "WX": WeakNext, "F": Eventually, "G": Always}
# Binary operators: binding strength and whether a chain of them nests to the right (else it is one n-ary node).
_BINARY = {"->": (1, True), "|": (2, False), "&": (3, False), "U": (4, True), "R": (4, True)}


class FormulaTooDeepError(ParseError):
    """A formula nests more than MAX_DEPTH operators, or its text opens more than MAX_PENDING operators and
    parentheses at once (refused by policy, not by Python's stack)."""

    def __init__(self, text: str, position: int) -> None:
        super().__init__(text, position, f"at most {MAX_DEPTH} nested operators", "a formula nested deeper")
        self.args = (f"at position {position}: formula nested too deeply; expected at most {MAX_DEPTH} nested "
                     f"operators (and {MAX_PENDING} open operators and parentheses)",)


@dataclass
class _Pending:
    """An operator on the parser's stack, waiting for its operands ("(" marks an open parenthesis)."""

    op: str
    position: int
    arity: int


def _node(op: str, args: list[tuple[Formula, int]]) -> tuple[Formula, int]:
    """The formula of an operator over its operands, with its depth (operands carry theirs)."""
    depth = 1 + max(d for _, d in args)
    items = tuple(f for f, _ in args)
    if op in _UNARY:
        return _UNARY[op](items[0]), depth
    if op == "&":
        return And(items), depth
    if op == "|":
        return Or(items), depth
    left, right = items
    return {"->": Implies, "U": Until, "R": Release}[op](left, right), depth


class _Parser:
    """Operator precedence parsing with explicit stacks: nesting is bounded by MAX_DEPTH, never by recursion."""

    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = _tokenize(text)
        self.operands: list[tuple[Formula, int]] = []
        self.operators: list[_Pending] = []

    def fail(self, i: int, expected: str) -> ParseError:
        where = self.tokens[i][1] if i < len(self.tokens) else len(self.text)
        found = "end of text" if i >= len(self.tokens) else repr(self.tokens[i][0])
        return ParseError(self.text, where, expected, found)

    def reduce(self) -> None:
        """Replace the top operator and its operands by the formula they make."""
        top = self.operators.pop()
        args = self.operands[-top.arity:]
        del self.operands[-top.arity:]
        node = _node(top.op, args)
        if node[1] > MAX_DEPTH:
            raise FormulaTooDeepError(self.text, top.position)
        self.operands.append(node)

    def open_depth(self) -> int:
        return sum(1 for entry in self.operators if entry.op == "(")

    def parse(self) -> Formula:
        if not self.tokens:
            raise ParseError(self.text, 0, "a formula", "end of text")
        i, n = 0, len(self.tokens)
        while True:
            # An operand: prefix operators and open parentheses first, then an atom.
            while i < n and (self.tokens[i][0] in _UNARY or self.tokens[i][0] == "("):
                token, position = self.tokens[i]
                self.operators.append(_Pending(token, position, 1))
                if len(self.operators) > MAX_PENDING:
                    raise FormulaTooDeepError(self.text, position)
                i += 1
            token = self.tokens[i][0] if i < n else None
            if token in ("true", "false"):
                self.operands.append((Const(token == "true"), 0))
            elif token == "END":
                self.operands.append((End(), 0))
            elif token is not None and token not in KEYWORDS and re.fullmatch(r"[A-Za-z_]\w*", token):
                self.operands.append((Prop(token), 0))
            else:
                raise self.fail(i, "a proposition, '!', 'X', 'F', 'G' or '('")
            i += 1
            # After an operand: close parentheses, then a binary operator or the end.
            while True:
                while self.operators and self.operators[-1].op in _UNARY:
                    self.reduce()
                token = self.tokens[i][0] if i < n else None
                if token != ")":
                    break
                if not self.open_depth():
                    raise self.fail(i, "an operator (&, |, ->, U, R) or end of text")
                while self.operators[-1].op != "(":
                    self.reduce()
                self.operators.pop()
                i += 1
            if token is None:
                if self.open_depth():
                    raise self.fail(i, "')'")
                while self.operators:
                    self.reduce()
                (formula, _), = self.operands
                return formula
            if token not in _BINARY:
                raise self.fail(i, "')'" if self.open_depth() else "an operator (&, |, ->, U, R) or end of text")
            strength, nests_right = _BINARY[token]
            while self.operators and self.operators[-1].op in _BINARY:
                top_strength = _BINARY[self.operators[-1].op][0]
                if top_strength > strength or (top_strength == strength and not nests_right
                                               and self.operators[-1].op != token):
                    self.reduce()
                else:
                    break
            top = self.operators[-1] if self.operators else None
            if top is not None and top.op == token and not nests_right:
                top.arity += 1  # a & b & c is one conjunction of three
            else:
                self.operators.append(_Pending(token, self.tokens[i][1], 2))
                if len(self.operators) > MAX_PENDING:
                    raise FormulaTooDeepError(self.text, self.tokens[i][1])
            i += 1


def parse(text: str, propositions: Iterable[str] | None = None) -> Formula:
    """Parse LTL text; with ``propositions`` given, unknown proposition names are an error."""
    if not isinstance(text, str):
        raise TypeError(f"formula text must be a string, got {type(text).__name__}")
    formula = _Parser(text).parse()
    if propositions is not None:
        known = set(propositions)
        unknown = atoms(formula) - known
        if unknown:
            raise UnknownPropositionError(unknown, known)
    return formula


def atoms(formula: Formula) -> set[str]:
    """The proposition names a formula mentions."""
    if isinstance(formula, Prop):
        return {formula.name}
    found: set[str] = set()
    for child in children(formula):
        found |= atoms(child)
    return found


def children(formula: Formula) -> tuple[Formula, ...]:
    """The direct subformulas of a formula."""
    if isinstance(formula, (And, Or)):
        return formula.args
    if isinstance(formula, (Implies, Until, Release)):
        return (formula.left, formula.right)
    if isinstance(formula, (Not, Next, WeakNext, Eventually, Always)):
        return (formula.arg,)
    return ()


# ---------------------------------------------------------------- printing

_PREFIX = {Next: "X", WeakNext: "WX", Eventually: "F", Always: "G"}


def to_text(formula: Formula) -> str:
    """Print a formula so that ``parse(to_text(f)) == f``; template clauses print as G(!p), F(p), (!b U a)."""
    if isinstance(formula, Const):
        return "true" if formula.value else "false"
    if isinstance(formula, Prop):
        return formula.name
    if isinstance(formula, End):
        return "END"
    if isinstance(formula, Not):
        return "!" + _operand(formula.arg)
    if type(formula) in _PREFIX:
        return f"{_PREFIX[type(formula)]}({to_text(formula.arg)})"
    if isinstance(formula, (Until, Release)):
        word = "U" if isinstance(formula, Until) else "R"
        return f"({_operand(formula.left)} {word} {_operand(formula.right)})"
    if isinstance(formula, And):
        return " & ".join(_operand(arg, allow=(Not, Until, Release)) for arg in formula.args)
    if isinstance(formula, Or):
        return " | ".join(_operand(arg, allow=(Not, Until, Release, And)) for arg in formula.args)
    if isinstance(formula, Implies):
        right = to_text(formula.right)
        left = _operand(formula.left, allow=(Not, Until, Release, And, Or))
        return f"{left} -> {right}"
    raise TypeError(f"not a formula: {formula!r}")


def _operand(formula: Formula, allow: tuple[type, ...] = ()) -> str:
    """Text of a subformula, parenthesised unless it binds at least as tightly as its context."""
    atomic = (Const, Prop, End, Not, Next, WeakNext, Eventually, Always, Until, Release)
    text = to_text(formula)
    if isinstance(formula, atomic) or isinstance(formula, allow):
        return text
    return f"({text})"
