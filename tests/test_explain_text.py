"""``print(graph.explain(node, predicate))`` reads like ``sgbelief explain``, not like a dataclass."""

from __future__ import annotations

from pathlib import Path

import pytest

from sgbelief.api.operators import make_operator
from sgbelief.api.scene_graph import SceneGraph
from sgbelief.cli import main
from sgbelief.fusion.channel import FrameLabels
from sgbelief.fusion.config import OperatorConfig
from sgbelief.testing import conformance_table, random_stream


def _graph() -> SceneGraph:
    table = conformance_table()
    op = make_operator("comod", OperatorConfig.from_mapping({"t_prov": 1_000_000, "tau_t": 0.1}), table)
    graph = SceneGraph(create_nodes=True)
    for ev, labels in random_stream(200, n_nodes=4, seed=3):
        op.update(graph, ev, FrameLabels(labels))
    return graph


def test_a_story_prints_as_the_command_shows_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    graph = _graph()
    node, predicate = max(graph.provenance.pairs(), key=lambda k: len(graph.provenance.entries(*k)))
    story = graph.explain(node, predicate)
    text = str(story)
    assert not text.startswith("BeliefStory(")
    assert text.splitlines()[0].startswith(f"{node!r} {predicate}: Beta(")
    assert "live events" in text and story.sentence in text and text.endswith(f"note: {story.not_recorded}.")
    assert sum(1 for line in text.splitlines() if line.startswith("    ") and line.split()[0].isdigit()) == min(
        40, len(story.events))
    graph.save(tmp_path / "map")
    capsys.readouterr()
    assert main(["explain", str(tmp_path / "map"), str(node), predicate]) == 0
    assert capsys.readouterr().out == SceneGraph.load(tmp_path / "map").explain(node, predicate).render() + "\n"
    assert len(story.render(limit=0, key=False).splitlines()) == len(story.render(limit=0).splitlines()) - 2
