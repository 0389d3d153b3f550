"""Exception types. Every error raised on bad input names the field (and line/file when known)."""

from __future__ import annotations

from collections.abc import Iterable


class SgbeliefError(Exception):
    """Base class of all sgbelief errors."""


class InvalidEventError(SgbeliefError, ValueError):
    """An evidence event violates Def. 2 (bad confidence, targeting mass, predicate, ...)."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(f"invalid evidence event: field '{field}': {message}")


class UnknownPredicateError(SgbeliefError, KeyError):
    """A predicate that the vocabulary does not define."""

    def __init__(self, predicate: str, known: Iterable[str]) -> None:
        self.predicate = predicate
        self.known = sorted(known)
        shown = ", ".join(self.known[:40]) + (" ..." if len(self.known) > 40 else "")
        super().__init__(f"unknown predicate {predicate!r}; known predicates: {shown}")

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0])


class UnknownNodeError(SgbeliefError, KeyError):
    """A node id that is not in the scene graph."""

    def __init__(self, node: object, event_id: str | None = None) -> None:
        self.node = node
        self.event_id = event_id
        if event_id is None:
            super().__init__(f"unknown node {node!r}")
        else:
            super().__init__(
                f"event {event_id!r} targets unknown node {node!r}: add it first (graph.add_node), or "
                "build the graph with create_nodes=True to let evidence create its nodes"
            )

    def __str__(self) -> str:
        return str(self.args[0])


class DuplicateEventError(SgbeliefError, ValueError):
    """An event id that the graph's provenance already holds: ids are unique within a graph, so
    that ``retract(id)`` names one event."""

    def __init__(self, event_id: str) -> None:
        self.event_id = event_id
        super().__init__(
            f"duplicate event id {event_id!r}: the graph already holds an event with this id "
            "(ids must be unique within a graph, so that retract(id) names one event)"
        )


class ConfigError(SgbeliefError, ValueError):
    """An invalid configuration value or file; the message names the key."""


class FormatError(SgbeliefError, ValueError):
    """A malformed file (JSON, JSONL, YAML, saved graph); the message names file, line and field."""

    def __init__(self, message: str, *, path: object = None, line: int | None = None) -> None:
        self.path = path
        self.line = line
        where = ""
        if path is not None:
            where = f"{path}"
            if line is not None:
                where += f":{line}"
            where += ": "
        elif line is not None:
            where = f"line {line}: "
        super().__init__(where + message)


class RetractionError(SgbeliefError, LookupError):
    """An event cannot be retracted (unknown id, or folded away by provenance compaction)."""


class QueueError(SgbeliefError, LookupError):
    """A queue operation on an event that is not pending (e.g. confirming a committed event)."""


class ChannelMismatchError(SgbeliefError, ValueError):
    """A geometric channel's labels match nothing in the vocabulary (or it gave none at all), so it
    could verify no claim: raised instead of letting the channel be silently off."""


# ---------------------------------------------------------------------------------- warnings
class SgbeliefWarning(UserWarning):
    """Base class of every warning sgbelief issues: a condition the user should hear about that
    does not stop the work (filter them all with ``warnings.simplefilter(..., SgbeliefWarning)``)."""


class SgbeliefDeprecationWarning(SgbeliefWarning, DeprecationWarning):
    """A name that moved or is going away; the message says where it lives now."""


def warn_at_caller(message: str, category: type[Warning]) -> None:
    """``warnings.warn`` attributed to the first frame outside the sgbelief package (the user's
    script, or ConceptGraphs' loop around a patched function), not to the line inside sgbelief
    that noticed the condition."""
    import inspect
    import os
    import warnings

    package = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = inspect.currentframe(), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package):
        frame, level = frame.f_back, level + 1
    del frame
    warnings.warn(message, category, stacklevel=level)


class LowConfidenceWarning(SgbeliefWarning):
    """Most claims carry a confidence below 0.5 and nothing can calibrate them (no geometric
    channel, and the operator configured without the agreement shift the ConceptGraphs backend
    uses by default): sgbelief reads a confidence as the probability that the claim is right, so
    each such claim counts against its class and objects are left unknown. The message gives the
    counts and what to pass instead."""


class InputMismatchWarning(SgbeliefWarning):
    """Two input files only partly describe the same map (a truth or nodes file that covers some
    of the nodes an evidence log targets): the message gives the counts."""
