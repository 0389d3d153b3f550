"""Docs that state facts about the code stay true: usage.md's command table names every required
option of each command, and visualisation.md describes the trace markers the legend draws."""

from __future__ import annotations

import argparse
import importlib
import re
from pathlib import Path

import pytest

from sgbelief.cli import COMMANDS

DOCS = Path(__file__).resolve().parents[1] / "docs"


def _command_rows() -> list[tuple[str, str]]:
    rows = []
    for line in (DOCS / "usage.md").read_text().splitlines():
        m = re.match(r"^\| `sgbelief ([a-z-]+)(.*?)\| ", line)
        if m:
            rows.append((m.group(1), m.group(2)))
    return rows


class _Recorder(argparse.ArgumentParser):
    """A parser that keeps the actions its command adds (options added to groups are not seen)."""

    def __init__(self, **kwargs: object) -> None:  # subcommand parsers are made with keywords
        self.recorded: list[argparse.Action] = []
        super().__init__(**kwargs)  # type: ignore[arg-type]

    def add_argument(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        action = super().add_argument(*args, **kwargs)
        self.recorded.append(action)
        return action


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_usage_table_names_every_required_option(command: str) -> None:
    rows = [text for name, text in _command_rows() if name == command]
    assert rows, f"usage.md's command table has no row for sgbelief {command}"
    parser = _Recorder()
    importlib.import_module(COMMANDS[command][0]).add_arguments(parser)
    required = [a.option_strings[0] for a in parser.recorded if a.required and a.option_strings]
    for option in required:
        assert any(option in text for text in rows), f"usage.md: sgbelief {command} row lacks required {option}"


def test_visualisation_describes_each_marker_shape_the_legend_draws() -> None:
    from sgbelief.viz.style import VERDICT_MARKERS

    glyph = {"X": "✕", "^": "▲", "o": "●"}
    text = (DOCS / "visualisation.md").read_text()
    para = text[text.index("one marker per event"):text.index("A compacted bucket is one diamond")]
    for verdict in ("⊥", "⊤", "∅"):
        assert f"{glyph[VERDICT_MARKERS[verdict]]} for {verdict}" in para, verdict
    assert "share one shape" not in para
