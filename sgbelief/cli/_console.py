"""What a command shows on the console besides its output: progress bars and warnings.

A progress bar appears only on a terminal: in a pipe or a log file the command's output stays
clean. Library code reports through :mod:`warnings` (user-facing conditions, e.g. a map without
geometry) or :mod:`logging`; :func:`route_messages` turns both into one line per message on
stderr, prefixed with the command's name, and keeps third-party loggers at WARNING.
"""

from __future__ import annotations

import logging
import re
import sys
from typing import Any, TextIO

_WARNING_LINE = re.compile(r"^.*?:\d+: \w+: (.*)$")


def progress(total: int | None = None, *, desc: str, unit: str, quiet: bool = False,
             stream: TextIO | None = None) -> Any:
    """A tqdm bar on stderr, disabled when ``quiet`` or when stderr is not a terminal."""
    from tqdm import tqdm

    stream = sys.stderr if stream is None else stream
    enabled = not quiet and bool(getattr(stream, "isatty", lambda: False)())
    return tqdm(total=total, desc=desc, unit=unit, file=stream, disable=not enabled, leave=False)


class _CommandFormatter(logging.Formatter):
    def __init__(self, command: str) -> None:
        super().__init__()
        self.command = command

    def format(self, record: logging.LogRecord) -> str:
        if record.name == "py.warnings":  # "path:line: Category: text\n  source": keep the text
            first = record.getMessage().strip().splitlines()[0]
            found = _WARNING_LINE.match(first)
            return f"sgbelief {self.command}: warning: {found.group(1) if found else first}"
        return f"sgbelief {self.command}: {record.levelname.lower()}: {record.getMessage()}"


def route_messages(command: str, stream: TextIO | None = None) -> logging.Handler:
    """Send warnings and log records of level WARNING and above to ``stream`` as one line each.

    Returns the handler so that a caller (a test, or ``main`` when it returns) can remove it.
    """
    handler = logging.StreamHandler(sys.stderr if stream is None else stream)
    handler.setFormatter(_CommandFormatter(command))
    handler.setLevel(logging.WARNING)
    root = logging.getLogger()
    root.addHandler(handler)
    if root.level == logging.NOTSET or root.level < logging.WARNING:
        root.setLevel(logging.WARNING)
    logging.captureWarnings(True)
    return handler


def unroute_messages(handler: logging.Handler) -> None:
    logging.getLogger().removeHandler(handler)
    logging.captureWarnings(False)
