"""The README's Python example runs as written; `sgbelief inspect` reads the map it saves."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from sgbelief.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    example = next(b for b in blocks if "make_operator" in b)
    monkeypatch.chdir(tmp_path)
    exec(compile(example, "README.md", "exec"), {})
    assert (tmp_path / "maps" / "seq00" / "graph.json").exists()
    capsys.readouterr()
    assert main(["inspect", "maps/seq00", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["nodes"] == 1 and summary["pending_disagreements"] == 1
    assert main(["inspect", "maps/seq00", "seq00/17"]) == 0
    text = capsys.readouterr().out
    assert "is_car" in text and "refused" in text
    assert main(["inspect", "maps/seq00", "nope"]) == 1
