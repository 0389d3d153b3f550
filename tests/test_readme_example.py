"""The README's replay -> show -> explain example shows what its text promises, on the demo's own
data (the outdoor suite of ``sgbelief bench``, seed 0): a map with refused claims ringed, and an
``explain`` of the named object with one line per claim about the car, refused ones among them."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from sgbelief.cli import main

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow  # ~30 s: the full-size outdoor suite, one replay, one picture


def _example() -> list[list[str]]:
    block = next(b for b in re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
                 if "sgbelief replay" in b)
    return [shlex.split(line)[1:] for line in block.replace("\\\n", " ").splitlines() if line.startswith("sgbelief ")]


def test_the_readme_example_draws_refusals_and_explains_the_car_event_by_event(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from sgbelief import SceneGraph
    from sgbelief.eval.benchmark import SUITES
    from sgbelief.eval.simulate import simulate
    from sgbelief.viz.map_state import map_state, nodes_by_scene

    replay, show, explain = _example()
    monkeypatch.chdir(tmp_path)
    simulate("outdoor", 0).write(Path("results/demo/data/outdoor"), profile="vlm_a", channel="oracle")  # as bench
    assert SUITES["outdoor"].vocab == "kitti360"
    assert main(replay) == 0
    assert main(show) == 0 and Path(show[show.index("--out") + 1]).stat().st_size > 50_000
    graph = SceneGraph.load(show[1])
    state = map_state(graph, nodes=nodes_by_scene(graph)[show[show.index("--scene") + 1]])
    assert state.folded == 0  # nothing of this scene is folded away
    assert len(state.refused) == 518  # the number the README gives
    node, predicate = explain[2], explain[3]
    assert state.sites()[0].node == node  # the object the map marks A
    capsys.readouterr()
    assert main(explain) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"'{node}' {predicate}: ") and "live events (67, time order)" in out
    claims = [line for line in out.splitlines() if re.match(r"^\s+\d+\s+e\d+\s", line)]
    assert len(claims) == 40  # the default --limit, of 67
    assert sum(" ⊥ " in line for line in claims) >= 15 and "30 ⊥" in out and "  compacted (" not in out
