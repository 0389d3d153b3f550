"""docs/queries.md's first Python example runs as written and prints what it shows (issue #21)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "queries.md"


def test_queries_doc_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    block = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)[0]
    exec(compile(block, "docs/queries.md", "exec"), {})
    printed = capsys.readouterr().out.strip().splitlines()
    shown = [line[2:] for line in block.splitlines() if line.startswith("# ") and line[2:3] in ("n", " ")]
    assert printed == shown
