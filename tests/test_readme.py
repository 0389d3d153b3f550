"""The documented examples run as written: docs/usage.md's Python example (and `sgbelief inspect`
on the map it saves), and every `sgbelief` command in the README's shell blocks, on the data a
small `sgbelief bench` writes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from sgbelief.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
USAGE = ROOT / "docs" / "usage.md"


def test_readme_python_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    blocks = re.findall(r"```python\n(.*?)```", USAGE.read_text(), flags=re.S)
    example = next(b for b in blocks if "make_operator" in b)
    monkeypatch.chdir(tmp_path)
    exec(compile(example, "docs/usage.md", "exec"), {})
    assert (tmp_path / "maps" / "seq00" / "graph.json").exists()
    capsys.readouterr()
    assert main(["inspect", "maps/seq00", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["nodes"] == 1 and summary["pending_disagreements"] == 1
    assert main(["inspect", "maps/seq00", "seq00/17"]) == 0
    text = capsys.readouterr().out
    assert "is_car" in text and "refused" in text
    assert main(["inspect", "maps/seq00", "nope"]) == 1


def _readme_commands() -> list[list[str]]:
    """The README's `sgbelief ...` shell lines (continuations joined), as argument lists."""
    import shlex

    commands = []
    for block in re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("sgbelief "):
                commands.append(shlex.split(line)[1:])
    return commands


def test_readme_commands_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Each command runs on a small bench's data (the README's node id is swapped for one the small
    outdoor suite has when it lacks it)."""
    commands = _readme_commands()
    assert [c[0] for c in commands] == ["replay", "show", "explain"]
    monkeypatch.chdir(tmp_path)
    assert main(["bench", "--suite", "outdoor", "--scale", "0.05", "--out", "results/demo", "--quiet",
                 "--no-real", "--no-retrieval", "--operators", "comod"]) == 0
    for cmd in commands:
        if cmd[0] == "explain":
            from sgbelief import SceneGraph

            graph = SceneGraph.load(cmd[1])
            if cmd[2] not in graph:
                cmd[2] = next(n for n in graph.nodes() if graph.provenance.predicates_of(n))
        capsys.readouterr()
        assert main(cmd) == 0, cmd
        out = capsys.readouterr().out
        assert out.strip(), cmd
    assert (tmp_path / "map.png").stat().st_size > 10_000
