"""One commit rule for queries (issue #21 item 10): retrieved means P > tau, as ``committed()`` and
``inspect``; ``--top`` / ``--all`` list fewer / more rows but count the retrieved ones."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sgbelief.cli import main
from sgbelief import SceneGraph
from sgbelief.query import run_query


def _graph() -> SceneGraph:
    g = SceneGraph()
    for i in range(8):  # Beta(1 + a, 1 + b): means 0.8 (x3), 0.5 (x3, at the prior), 0.25 (x2)
        g.add_node(f"n{i}")
        a, b = (3.0, 0.0) if i < 3 else (1.0, 1.0) if i < 6 else (0.0, 2.0)
        g.provenance.record(f"n{i}", "is_car", f"e{i}", 0, a, b)
    return g


def test_nodes_at_tau_are_not_retrieved_like_committed() -> None:
    g = _graph()
    res = run_query(g, "is_car", tau=0.5)
    assert res.nodes == ["n0", "n1", "n2"] == sorted(g.committed("is_car"))
    assert res.n_retrieved == 3
    everything = run_query(g, "is_car", tau=0.5, include_all=True)
    assert len(everything) == 8 and everything.n_retrieved == 3
    assert [m.retrieved for m in everything] == [True] * 3 + [False] * 5


def test_top_and_all_keep_the_retrieved_count(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _graph().save(tmp_path / "map")
    assert main(["query", str(tmp_path / "map"), "is_car", "--top", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["n_retrieved"] == 3 and doc["n_listed"] == 2 and len(doc["results"]) == 2
    assert main(["query", str(tmp_path / "map"), "is_car", "--all"]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert "3 retrieved (P > tau) of 8 candidates; 8 listed" in head
    assert main(["query", str(tmp_path / "map"), "is_car"]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert "3 retrieved (P > tau) of 8 candidates;" in head and "listed" not in head
