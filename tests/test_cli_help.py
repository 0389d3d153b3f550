"""Every option of every command has help text that states its default (issue #21)."""

from __future__ import annotations

import argparse
import importlib

import pytest

from sgbelief.cli import COMMANDS


def _parser(name: str) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog=f"sgbelief {name}")
    importlib.import_module(COMMANDS[name][0]).add_arguments(parser)
    return parser


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_option_has_help_with_its_default(name: str) -> None:
    parser = _parser(name)
    missing = []
    for action in parser._actions:
        if not action.option_strings or action.required or isinstance(action, argparse._HelpAction):
            continue
        text = (action.help or "") % {"default": action.default, "dest": action.dest}
        if not text or "default" not in text.lower():
            missing.append(action.option_strings[0])
    assert not missing, f"{name}: options without help stating the default: {missing}"


def test_output_folders_and_bench_data_are_named_in_help() -> None:
    bench = _parser("bench").format_help()
    assert "results/bench" in bench and "data/<suite>/events.jsonl" in bench and "nodes.json" in bench
    assert "results/import-cg" in _parser("import-cg").format_help()
