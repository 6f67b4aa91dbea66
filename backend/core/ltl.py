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


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.tokens = _tokenize(text)
        self.i = 0

    def peek(self) -> str | None:
        return self.tokens[self.i][0] if self.i < len(self.tokens) else None

    def where(self) -> int:
        return self.tokens[self.i][1] if self.i < len(self.tokens) else len(self.text)

    def found(self) -> str:
        token = self.peek()
        return "end of text" if token is None else repr(token)

    def expect(self, token: str) -> None:
        if self.peek() != token:
            raise ParseError(self.text, self.where(), repr(token), self.found())
        self.i += 1

    def parse(self) -> Formula:
        if not self.tokens:
            raise ParseError(self.text, 0, "a formula", "end of text")
        formula = self.implication()
        if self.peek() is not None:
            raise ParseError(self.text, self.where(), "an operator (&, |, ->, U, R) or end of text", self.found())
        return formula

    def implication(self) -> Formula:
        left = self.disjunction()
        if self.peek() == "->":
            self.i += 1
            return Implies(left, self.implication())
        return left

    def disjunction(self) -> Formula:
        items = [self.conjunction()]
        while self.peek() == "|":
            self.i += 1
            items.append(self.conjunction())
        return disj(items)

    def conjunction(self) -> Formula:
        items = [self.binary_temporal()]
        while self.peek() == "&":
            self.i += 1
            items.append(self.binary_temporal())
        return conj(items)

    def binary_temporal(self) -> Formula:
        left = self.unary()
        if self.peek() == "U":
            self.i += 1
            return Until(left, self.binary_temporal())
        if self.peek() == "R":
            self.i += 1
            return Release(left, self.binary_temporal())
        return left

    def unary(self) -> Formula:
        token = self.peek()
        unary_ops = {"!": Not, "X": Next, "WX": WeakNext, "F": Eventually, "G": Always}
        if token in unary_ops:
            self.i += 1
            return unary_ops[token](self.unary())
        if token == "(":
            self.i += 1
            inner = self.implication()
            self.expect(")")
            return inner
        if token in ("true", "false"):
            self.i += 1
            return Const(token == "true")
        if token == "END":
            self.i += 1
            return End()
        if token is not None and token not in KEYWORDS and re.fullmatch(r"[A-Za-z_]\w*", token):
            self.i += 1
            return Prop(token)
        raise ParseError(self.text, self.where(), "a proposition, '!', 'X', 'F', 'G' or '('", self.found())


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
