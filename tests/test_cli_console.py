"""Console behaviour of the commands: progress bars only on a terminal, warnings as one line each."""

from __future__ import annotations

import io
import logging
import warnings

from sgbelief.cli import _console as console


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_is_silent_in_a_pipe() -> None:
    pipe = io.StringIO()
    with console.progress(10, desc="replay", unit="ev", stream=pipe) as bar:
        shown = not bar.disable
        bar.update(10)
    assert not shown and pipe.getvalue() == ""


def test_progress_bar_shows_on_a_terminal_unless_quiet() -> None:
    tty = _Tty()
    with console.progress(10, desc="replay", unit="ev", stream=tty) as bar:
        shown = not bar.disable
        bar.update(10)
    assert shown and "replay" in tty.getvalue()
    quiet = _Tty()
    with console.progress(10, desc="replay", unit="ev", stream=quiet, quiet=True) as bar:
        shown = not bar.disable
        bar.update(10)
    assert not shown and quiet.getvalue() == ""


def test_warnings_and_log_records_become_one_prefixed_line() -> None:
    err = io.StringIO()
    handler = console.route_messages("replay", stream=err)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.warn("the map has no geometry", UserWarning)
        logging.getLogger("sgbelief.cli.replay").warning("no nodes.json beside %s", "events.jsonl")
        logging.getLogger("somelib").info("chatter a user never asked for")
    finally:
        console.unroute_messages(handler)
    assert err.getvalue().splitlines() == [
        "sgbelief replay: warning: the map has no geometry",
        "sgbelief replay: warning: no nodes.json beside events.jsonl",
    ]
