"""Command-line interface: ``sgbelief <command> ...``.

Each command lives in its own module ``sgbelief.cli.<module>`` that defines
``add_arguments(parser)`` and ``run(args) -> int``; modules are imported only
when their command runs, so ``sgbelief --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

# command -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "replay": ("sgbelief.cli.replay", "replay an evidence log through several fusion operators"),
    "bench": ("sgbelief.cli.bench", "run the simulated suites and reproduce the paper's tables"),
    "query": ("sgbelief.cli.query", "ask a compound query of a saved scene graph"),
    "refer": ("sgbelief.cli.refer", "the one object a referring utterance names (\"the chair closest to the door\")"),
    "retrieval": ("sgbelief.cli.retrieval", "compound-query retrieval F1 per operator"),
    "import-cg": ("sgbelief.cli.import_cg", "import a saved ConceptGraphs map and replay its detections"),
    "inspect": ("sgbelief.cli.inspect", "show a saved graph's beliefs and provenance"),
    "explain": ("sgbelief.cli.explain", "a belief's story: every event of a (node, predicate), and why it is committed"),
    "vocab": ("sgbelief.cli.vocab", "check an open-vocabulary class list: what contradicts what"),
    "show": ("sgbelief.cli.show", "draw a saved map top-down (PNG), or one element's belief trace"),
    "record": ("sgbelief.cli.record", "replay an evidence log into a rerun recording (.rrd; sgbelief[rerun])"),
}


def build_parser() -> argparse.ArgumentParser:
    from sgbelief import __version__

    parser = argparse.ArgumentParser(
        prog="sgbelief",
        description="Calibrated, provenance-tracked beliefs for 3D scene graphs.",
    )
    parser.add_argument("--version", action="version", version=f"sgbelief {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_module, help_text) in COMMANDS.items():
        sub.add_parser(name, help=help_text, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in {"-h", "--help", "--version"} or argv[0] not in COMMANDS:
        parser = build_parser()
        if not argv:
            parser.print_help()
            return 2
        parser.parse_args(argv)  # prints help/version or an "invalid choice" error
        return 2
    name, rest = argv[0], argv[1:]
    module = importlib.import_module(COMMANDS[name][0])
    parser = argparse.ArgumentParser(prog=f"sgbelief {name}", description=COMMANDS[name][1])
    module.add_arguments(parser)
    args = parser.parse_args(rest)
    import warnings

    from sgbelief.cli._console import route_messages, unroute_messages
    from sgbelief.errors import SgbeliefError, SgbeliefWarning

    handler = route_messages(name)
    try:
        with warnings.catch_warnings():
            # a command's own warnings are messages to its user: each one a line on stderr, whatever
            # the interpreter's filters (a test suite that makes them errors reads them there)
            warnings.simplefilter("always", SgbeliefWarning)
            rc = int(module.run(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit flush
        return rc
    except BrokenPipeError:
        # the reader went away (``sgbelief query MAP is_car | head -2``): stop quietly, as a SIGPIPE'd tool does
        _silence_stdout()
        return 141
    except SgbeliefError as exc:
        print(f"sgbelief {name}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a file that is not there, or cannot be read or written
        if exc.filename is None and not isinstance(exc, FileNotFoundError):
            raise
        print(f"sgbelief {name}: error: {_os_error(exc)}", file=sys.stderr)
        return 1
    finally:
        unroute_messages(handler)


def _os_error(exc: OSError) -> str:
    """One line naming the file: ``events.jsonl: no such file or directory`` (not ``[Errno 2] ...``)."""
    if exc.filename is None or exc.strerror is None:  # raised with a message of its own
        return str(exc)
    return f"{exc.filename}: {exc.strerror[:1].lower()}{exc.strerror[1:]}"


def _silence_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush does not raise again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # stdout replaced (tests) or already closed
        pass


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
