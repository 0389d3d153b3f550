from __future__ import annotations

import pytest

from sgbelief.errors import SgbeliefError
from sgbelief.query import Compound, Literal, P, QuerySyntaxError, parse


def test_conjunction_and_negation():
    c = parse("is_car & is_stationary & is_near_road_px & !is_near_pedestrian")
    assert c.literals == (Literal("is_car"), Literal("is_stationary"), Literal("is_near_road_px"),
                          Literal("is_near_pedestrian", True))
    assert str(c) == "is_car & is_stationary & is_near_road_px & !is_near_pedestrian"


def test_precedence_negation_binds_tighter_than_and():
    c = parse("!a & b")
    assert c.literals == (Literal("a", True), Literal("b"))
    assert parse("not a and b") == c == parse("~a && b")


def test_parentheses_group_and_flatten():
    assert parse("a & (b & (c & !d))") == parse("a & b & c & !d")


def test_double_negation_and_duplicates():
    assert parse("!!a") == parse("a")
    assert parse("a & a & !b & !b").literals == (Literal("a"), Literal("b", True))


def test_builder_equivalent_and_roundtrip():
    built = P("is_car") & P("is_stationary") & ~P("is_near_pedestrian")
    parsed = parse("is_car & is_stationary & !is_near_pedestrian")
    assert built == parsed
    assert parse(str(built)) == built
    assert isinstance(built, Compound)
    with pytest.raises(TypeError):
        ~(P("a") & P("b"))


@pytest.mark.parametrize(
    ("expr", "pos", "needle"),
    [
        ("is_car & | is_x", 9, "unexpected character '|'"),
        ("is_car is_x", 7, "expected '&'"),
        ("is_car &", 8, "end of the expression"),
        ("& is_car", 0, "expected a predicate"),
        ("!(a & b)", 1, "negation applies to a single predicate"),
        ("(a & b", 6, "expected ')'"),
        ("a & b)", 5, "unexpected ')'"),
        ("a & ()", 5, "empty parentheses"),
        ("a & 3b", 4, "unexpected character '3'"),
        ("   ", 0, "empty query"),
    ],
)
def test_errors_point_at_offending_token(expr, pos, needle):
    with pytest.raises(QuerySyntaxError) as ei:
        parse(expr)
    err = ei.value
    assert err.position == pos
    assert needle in str(err)
    lines = str(err).splitlines()
    # the caret line puts '^' under the offending column
    assert lines[-1].index("^") - 2 == pos
    assert isinstance(err, SgbeliefError)
