"""Python-API and query input that used to slip through or mislead (issue #21 item 13)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief.errors import InvalidEventError
from sgbelief.fusion.events import EvidenceEvent
from sgbelief import SceneGraph
from sgbelief.query import run_query
from sgbelief.query.named import UnknownNamedQueryError


def test_negative_event_time_is_rejected_like_the_file_reader() -> None:
    with pytest.raises(InvalidEventError, match="field 't': must be a non-negative integer"):
        EvidenceEvent({"a": 1.0}, "is_car", 0.9, t=-1)
    assert EvidenceEvent({"a": 1.0}, "is_car", 0.9, t=0).t == 0


def test_mistyped_named_query_suggests_the_closest(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    g = SceneGraph()
    g.add_node("c")
    g.provenance.record("c", "is_car", "e1", 0, 3.0, 0.0)
    with pytest.raises(UnknownNamedQueryError) as ei:
        run_query(g, "car near unicorn")
    assert "no such named query 'car near unicorn'; did you mean" in str(ei.value)
    assert "car near pedestrian" in ei.value.suggestions
    g.save(tmp_path / "map")
    assert main(["query", str(tmp_path / "map"), "car near unicorn"]) == 1
    err = capsys.readouterr().err
    assert "no such named query" in err and "'car near pedestrian'" in err and "position" not in err
    # a real expression with a syntax error still gets the positioned syntax error
    assert main(["query", str(tmp_path / "map"), "is_car & & is_stationary"]) == 1
    assert "position" in capsys.readouterr().err
    assert main(["query", str(tmp_path / "map"), "car near pedestrian"]) == 0
