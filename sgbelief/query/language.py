"""Compound-query language and its Python builder.

Grammar (whitespace is insignificant; ``and`` / ``not`` are keyword spellings of ``&`` / ``!``)::

    query     := conjunct ( ("&" | "and") conjunct )*
    conjunct  := ("!" | "~" | "not") conjunct  |  "(" query ")"  |  PREDICATE
    PREDICATE := [A-Za-z_][A-Za-z0-9_]*          (e.g. is_car, is_near_window)

``!`` binds tighter than ``&``; parentheses only group (a conjunction is flat, so
``a & (b & c)`` is ``a & b & c``); negation applies to a single predicate (``!(a & b)`` is
rejected: its probability is not a product of component probabilities). ``!!a`` is ``a``.
A repeated literal is kept once; ``a & !a`` is allowed (it is never retrieved).

The builder is equivalent: ``P("is_car") & P("is_stationary") & ~P("is_near_pedestrian")``
gives the same :class:`Compound` as parsing ``"is_car & is_stationary & !is_near_pedestrian"``,
and ``str(compound)`` prints the canonical expression (parses back to an equal compound).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

from sgbelief.errors import SgbeliefError, UnknownPredicateError

__all__ = ["Literal", "Compound", "P", "parse", "QuerySyntaxError", "QueryPredicateError", "caret"]


def caret(expression: str, position: int, length: int = 1) -> str:
    """Two lines: the expression and a caret under ``position`` (``length`` carets)."""
    return f"  {expression}\n  {' ' * position}{'^' * max(1, length)}"


class QuerySyntaxError(SgbeliefError, ValueError):
    """A malformed query expression; ``position`` is the 0-based offset of the offending token."""

    def __init__(self, message: str, expression: str, position: int, length: int = 1) -> None:
        self.expression = expression
        self.position = position
        self.reason = message
        super().__init__(f"{message} at position {position}:\n{caret(expression, position, length)}")


class QueryPredicateError(UnknownPredicateError):
    """An unknown predicate inside an expression: names the token's position and the known names."""

    def __init__(self, predicate: str, known: Iterable[str], expression: str, position: int) -> None:
        super().__init__(predicate, known)
        self.expression = expression
        self.position = position
        self.args = (f"{self.args[0]}\nat position {position}:\n{caret(expression, position, len(predicate))}",)


@dataclass(frozen=True)
class Literal:
    """One component: a predicate name, possibly negated; ``position`` is where it was parsed
    (-1 when built in Python) and does not take part in equality."""

    name: str
    negated: bool = False
    position: int = -1

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Literal) and (self.name, self.negated) == (other.name, other.negated)

    def __hash__(self) -> int:
        return hash((self.name, self.negated))

    def __str__(self) -> str:
        return ("!" if self.negated else "") + self.name

    def __invert__(self) -> Literal:
        return Literal(self.name, not self.negated, self.position)

    def __and__(self, other: Literal | Compound) -> Compound:
        return Compound((self,)) & other


@dataclass(frozen=True)
class Compound:
    """A conjunction of literals (order of first appearance, duplicates dropped)."""

    literals: tuple[Literal, ...]
    expression: str = ""

    def __post_init__(self) -> None:
        if not self.literals:
            raise ValueError("a compound needs at least one predicate")
        seen: dict[Literal, None] = {}
        for lit in self.literals:
            seen.setdefault(lit, None)
        object.__setattr__(self, "literals", tuple(seen))
        if not self.expression:
            object.__setattr__(self, "expression", " & ".join(map(str, self.literals)))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Compound) and self.literals == other.literals

    def __hash__(self) -> int:
        return hash(self.literals)

    def __str__(self) -> str:
        return " & ".join(map(str, self.literals))

    def __and__(self, other: Literal | Compound) -> Compound:
        more = (other,) if isinstance(other, Literal) else tuple(other.literals)
        return Compound(self.literals + more)

    def __invert__(self) -> Compound:
        if len(self.literals) != 1:
            raise TypeError("negation applies to a single predicate, not to a conjunction")
        return Compound((~self.literals[0],))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(lit.name for lit in self.literals)


def P(name: str) -> Compound:
    """Builder: a one-predicate compound; combine with ``&`` and negate with ``~``."""
    if not _IDENT.fullmatch(name):
        raise QuerySyntaxError("invalid predicate name", name, 0, max(1, len(name)))
    return Compound((Literal(name),))


_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_TOKEN = re.compile(r"\s*(?:(?P<op>&&|&|!|~|\(|\))|(?P<ident>[A-Za-z_][A-Za-z0-9_]*)|(?P<bad>\S))")
_AND_WORDS = {"and", "AND"}
_NOT_WORDS = {"not", "NOT"}


def _tokenize(expr: str) -> list[tuple[str, str, int]]:
    """(kind, text, position) with kind in {'&', '!', '(', ')', 'ident', 'end'}."""
    tokens: list[tuple[str, str, int]] = []
    pos = 0
    n = len(expr)
    while pos < n:
        m = _TOKEN.match(expr, pos)
        if m is None:  # only trailing whitespace left
            break
        if m.group("op"):
            text = m.group("op")
            kind = {"&&": "&", "&": "&", "!": "!", "~": "!", "(": "(", ")": ")"}[text]
            tokens.append((kind, text, m.start("op")))
        elif m.group("ident"):
            text = m.group("ident")
            kind = "&" if text in _AND_WORDS else "!" if text in _NOT_WORDS else "ident"
            tokens.append((kind, text, m.start("ident")))
        else:
            start = m.start("bad")
            ch = m.group("bad")
            hint = " (only conjunction '&' and negation '!' are supported)" if ch in "|,+-" else ""
            raise QuerySyntaxError(f"unexpected character {ch!r}{hint}", expr, start)
        pos = m.end()
    tokens.append(("end", "", len(expr.rstrip()) if expr.strip() else 0))
    return tokens


class _Parser:
    def __init__(self, expr: str) -> None:
        self.expr = expr
        self.tokens = _tokenize(expr)
        self.i = 0

    def peek(self) -> tuple[str, str, int]:
        return self.tokens[self.i]

    def take(self) -> tuple[str, str, int]:
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def error(self, message: str, tok: tuple[str, str, int]) -> QuerySyntaxError:
        return QuerySyntaxError(message, self.expr, tok[2], max(1, len(tok[1])))

    def query(self) -> list[Literal]:
        lits = self.conjunct()
        while self.peek()[0] == "&":
            self.take()
            lits += self.conjunct()
        return lits

    def conjunct(self) -> list[Literal]:
        kind, text, pos = tok = self.peek()
        if kind == "!":
            self.take()
            nxt = self.peek()
            if nxt[0] == "(":
                raise self.error("negation applies to a single predicate, not to a parenthesised group", nxt)
            inner = self.conjunct()
            return [~inner[0]]
        if kind == "(":
            self.take()
            if self.peek()[0] == ")":
                raise self.error("empty parentheses", self.peek())
            lits = self.query()
            close = self.peek()
            if close[0] != ")":
                raise self.error("expected ')' to close the '(' at position %d" % pos, close)
            self.take()
            return lits
        if kind == "ident":
            self.take()
            return [Literal(text, False, pos)]
        if kind == "end":
            raise self.error("expected a predicate, got the end of the expression", tok)
        raise self.error(f"expected a predicate, got {text!r}", tok)


def parse(expr: str) -> Compound:
    """Parse an expression into a :class:`Compound` (raises :class:`QuerySyntaxError`)."""
    if not isinstance(expr, str):
        raise TypeError(f"query expression must be a str, got {type(expr).__name__}")
    if not expr.strip():
        raise QuerySyntaxError("empty query", expr, 0)
    p = _Parser(expr)
    lits = p.query()
    tok = p.peek()
    if tok[0] != "end":
        if tok[0] == "ident":
            raise p.error(f"expected '&' between predicates, got {tok[1]!r}", tok)
        raise p.error(f"unexpected {tok[1]!r}", tok)
    return Compound(tuple(lits), expression=expr.strip())
