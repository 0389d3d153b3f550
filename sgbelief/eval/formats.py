"""Evidence-log file formats: ``events.jsonl``, ``truth.json`` and ``nodes.json`` (see docs/formats.md).

``events.jsonl`` holds one evidence event per line (Def. 2 of the paper, plus the geometric
channel's label at the event's time for each targeted node)::

    {"t": 3, "id": "e0000012", "targets": {"d00/0007": 0.81, "d00/0009": 0.04},
     "predicate": "is_car", "confidence": 0.93, "context": "vlm_a",
     "geometric": {"d00/0007": "car", "d00/0009": null}}

An optional first line ``{"format": "sgbelief.events", "version": 1}`` identifies the file.

Validation strategy: every line goes through a hand-written check (no pydantic in the hot loop);
a line the check rejects is re-validated with the pydantic model :class:`EventModel` only to
produce a precise message naming the field.  ``tests/test_formats.py`` checks that both paths
accept and reject the same inputs.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from sgbelief.graph.persistence import atomic_write_text
from sgbelief.errors import FormatError

EVENTS_FORMAT = "sgbelief.events"
TRUTH_FORMAT = "sgbelief.truth"
NODES_FORMAT = "sgbelief.nodes"
FORMAT_VERSION = 1
MASS_SUM_TOLERANCE = 1e-6  # sum(T) <= 1 + tolerance (rounding in writers)

__all__ = [
    "EVENTS_FORMAT",
    "TRUTH_FORMAT",
    "NODES_FORMAT",
    "FORMAT_VERSION",
    "EventRecord",
    "EventModel",
    "NodeInfo",
    "SceneInfo",
    "NodesFile",
    "ReadStats",
    "validate_event",
    "event_to_json",
    "iter_events",
    "read_events",
    "write_events",
    "read_truth",
    "write_truth",
    "read_nodes",
    "write_nodes",
]


class EventRecord(NamedTuple):
    """A validated evidence event as read from ``events.jsonl`` (lightweight, no pydantic)."""

    t: int
    targets: dict[str, float]
    predicate: str
    confidence: float
    context: str
    geometric: dict[str, str | None]
    id: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of this record, keys in canonical order (``id`` omitted when None)."""
        out: dict[str, Any] = {"t": self.t}
        if self.id is not None:
            out["id"] = self.id
        out["targets"] = self.targets
        out["predicate"] = self.predicate
        out["confidence"] = self.confidence
        out["context"] = self.context
        out["geometric"] = self.geometric
        return out


# --------------------------------------------------------------------------- pydantic models


class EventModel(BaseModel):
    """Pydantic schema of one ``events.jsonl`` line (used for error messages and documentation)."""

    model_config = ConfigDict(extra="ignore", strict=True)

    t: int = Field(ge=0, description="time step (non-negative integer, non-decreasing in a file)")
    id: str | None = Field(default=None, description="optional event id (for retraction / provenance)")
    targets: dict[str, float] = Field(description="targeting distribution T: node -> mass in [0, 1]")
    predicate: str = Field(min_length=1)
    confidence: float = Field(description="raw foundation-model confidence c in [0, 1]")
    context: str = Field(min_length=1, description="context tag kappa (model / prompt identity)")
    geometric: dict[str, str | None] = Field(
        default_factory=dict, description="geometric label at (node, t) per targeted node; null = cannot assert"
    )

    @field_validator("t", mode="before")
    @classmethod
    def _no_bool_t(cls, v: Any) -> Any:
        if isinstance(v, bool):
            raise ValueError("must be an integer, not a boolean")
        return v

    @field_validator("confidence", mode="before")
    @classmethod
    def _conf(cls, v: Any) -> Any:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError("must be a number")
        v = float(v)
        if not math.isfinite(v) or not 0.0 <= v <= 1.0:
            raise ValueError(f"must be a finite number in [0, 1], got {v!r}")
        return v

    @field_validator("targets", mode="before")
    @classmethod
    def _targets(cls, v: Any) -> Any:
        if not isinstance(v, dict):
            raise ValueError("must be an object {node: mass}")
        out = {}
        total = 0.0
        for node, m in v.items():
            if isinstance(m, bool) or not isinstance(m, (int, float)):
                raise ValueError(f"mass of node {node!r} must be a number")
            m = float(m)
            if not math.isfinite(m) or not 0.0 <= m <= 1.0:
                raise ValueError(f"mass of node {node!r} must be in [0, 1], got {m!r}")
            total += m
            out[node] = m
        if total > 1.0 + MASS_SUM_TOLERANCE:
            raise ValueError(f"masses sum to {total:.6g} > 1")
        return out

    @model_validator(mode="after")
    def _geometric_keys(self) -> EventModel:
        extra = [n for n in self.geometric if n not in self.targets]
        if extra:
            raise ValueError(f"field 'geometric': node {extra[0]!r} is not a target of the event")
        return self


class _Header(BaseModel):
    model_config = ConfigDict(extra="forbid")
    format: str
    version: int


class NodeInfo(BaseModel):
    """Per-node geometry and attributes in ``nodes.json`` (see docs/formats.md)."""

    model_config = ConfigDict(extra="allow")

    scene: str = Field(description="sequence / scene id the node belongs to")
    label: str = Field(description="true (ground-truth) class label, vocabulary label name")
    centroid: tuple[float, float, float]
    bbox_min: tuple[float, float, float]
    bbox_max: tuple[float, float, float]
    first_seen: int | None = Field(default=None, description="first time step the element is in view")
    last_seen: int | None = Field(default=None, description="last time step the element is in view")
    front: tuple[float, float, float] | None = Field(default=None, description="unit horizontal front direction")
    track: list[tuple[int, float, float, float]] | None = Field(
        default=None, description="centroid over time [[t, x, y, z], ...] (outdoor)"
    )
    attributes: dict[str, float | bool | str | None] = Field(
        default_factory=dict, description="raw scene measurements (distances, speeds, ...)"
    )
    geometric_predicates: dict[str, bool] = Field(
        default_factory=dict, description="geometric-channel context predicates (authoritative), e.g. is_stationary"
    )

    @model_validator(mode="after")
    def _bbox(self) -> NodeInfo:
        if any(lo > hi for lo, hi in zip(self.bbox_min, self.bbox_max)):
            raise ValueError("bbox_min must be <= bbox_max componentwise")
        return self


class SceneInfo(BaseModel):
    """Per-scene / per-sequence information in ``nodes.json``."""

    model_config = ConfigDict(extra="allow")

    kind: str = Field(description="'outdoor' or 'indoor'")
    t_start: int
    t_end: int
    ego_track: list[tuple[int, float, float, float, float]] = Field(
        default_factory=list, description="camera pose over time [[t, x, y, z, yaw], ...]"
    )


class NodesFile(BaseModel):
    """The whole ``nodes.json`` document."""

    model_config = ConfigDict(extra="forbid")

    format: str = NODES_FORMAT
    version: int = FORMAT_VERSION
    suite: str = ""
    scenes: dict[str, SceneInfo] = Field(default_factory=dict)
    nodes: dict[str, NodeInfo]
    geometric_thresholds: dict[str, float] = Field(
        default_factory=dict, description="thresholds used to derive geometric_predicates"
    )


# --------------------------------------------------------------------------- fast validation


class _Bad(Exception):
    """Internal: the fast path rejected a line."""


def _fast_check(obj: Any) -> EventRecord:
    """Hand-written validation of one parsed line; raises ``_Bad`` on any problem."""
    if type(obj) is not dict:
        raise _Bad
    t = obj.get("t")
    if type(t) is not int or t < 0:
        raise _Bad
    targets = obj.get("targets")
    if type(targets) is not dict:
        raise _Bad
    total = 0.0
    for m in targets.values():
        tm = type(m)
        if tm is float:
            if not 0.0 <= m <= 1.0:  # NaN fails both comparisons
                raise _Bad
        elif tm is int:
            if not 0 <= m <= 1:
                raise _Bad
        else:
            raise _Bad
        total += m
    if total > 1.0 + MASS_SUM_TOLERANCE:
        raise _Bad
    pred = obj.get("predicate")
    if type(pred) is not str or not pred:
        raise _Bad
    c = obj.get("confidence")
    tc = type(c)
    if tc is float:
        if not 0.0 <= c <= 1.0:
            raise _Bad
    elif tc is int:
        if not 0 <= c <= 1:
            raise _Bad
        c = float(c)
    else:
        raise _Bad
    ctx = obj.get("context")
    if type(ctx) is not str or not ctx:
        raise _Bad
    geo = obj.get("geometric", None)
    if geo is None:
        if "geometric" in obj:
            raise _Bad
        geo = {}
    elif type(geo) is not dict:
        raise _Bad
    else:
        for n, lab in geo.items():
            if n not in targets or (lab is not None and type(lab) is not str):
                raise _Bad
    eid = obj.get("id")
    if eid is not None and type(eid) is not str:
        raise _Bad
    if _has_int_masses(targets):
        targets = {n: float(m) for n, m in targets.items()}
    return EventRecord(t, targets, pred, c, ctx, geo, eid)


def _has_int_masses(targets: dict[str, Any]) -> bool:
    """True if some mass is a JSON integer (0 or 1) that must be converted to float."""
    for m in targets.values():
        if type(m) is int:
            return True
    return False


def _pydantic_message(obj: Any) -> str:
    """A precise message for an invalid event object, naming the field."""
    if not isinstance(obj, dict):
        return f"an event must be a JSON object, got {type(obj).__name__}"
    try:
        EventModel.model_validate(obj)
    except ValidationError as exc:
        parts = []
        for err in exc.errors():
            loc = ".".join(str(p) for p in err["loc"]) or "(event)"
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            parts.append(f"field '{loc}': {msg}")
        return "; ".join(parts)
    return "invalid event (rejected by the fast validator)"  # pragma: no cover - paths agree (tested)


def validate_event(obj: Any, *, path: object = None, line: int | None = None) -> EventRecord:
    """Validate one parsed JSON object as an event; raise :class:`FormatError` naming the field."""
    try:
        return _fast_check(obj)
    except _Bad:
        raise FormatError(_pydantic_message(obj), path=path, line=line) from None


# --------------------------------------------------------------------------- events.jsonl


@dataclass
class ReadStats:
    """Counters filled by :func:`iter_events`."""

    lines: int = 0  # physical lines read (including header and blank lines)
    events: int = 0  # valid events yielded
    skipped: int = 0  # malformed lines skipped (only with skip_bad_lines=True)
    header: dict[str, Any] | None = None
    errors: list[str] = field(default_factory=list)  # first ``max_errors`` messages of skipped lines
    max_errors: int = 20


def _check_header(obj: dict[str, Any], expected: str, path: object, line: int | None) -> None:
    try:
        h = _Header.model_validate(obj)
    except ValidationError as exc:
        raise FormatError(f"bad header: {exc.errors()[0]['msg']}", path=path, line=line) from None
    if h.format != expected:
        raise FormatError(f"field 'format': expected {expected!r}, got {h.format!r}", path=path, line=line)
    if h.version > FORMAT_VERSION or h.version < 1:
        raise FormatError(
            f"field 'version': unsupported version {h.version} (this reader supports 1..{FORMAT_VERSION})",
            path=path,
            line=line,
        )


def iter_events(
    path: str | os.PathLike[str], *, skip_bad_lines: bool = False, stats: ReadStats | None = None
) -> Iterator[EventRecord]:
    """Stream validated events from an ``events.jsonl`` file, one line at a time.

    A malformed line raises :class:`FormatError` (file, 1-based line number, field) unless
    ``skip_bad_lines`` is set, in which case it is counted in ``stats.skipped``.  A line that is not
    UTF-8 is such a malformed line, and so is an event whose ``id`` an earlier line of the file
    already used (ids are unique within a log: ``retract(id)`` must name one claim).  Blank lines are
    ignored; an optional header object may only appear as the first non-blank line.
    """
    st = stats if stats is not None else ReadStats()
    loads = json.loads
    first = True
    seen_ids: set[str] = set()
    # read bytes and decode line by line: a non-UTF-8 byte is a bad line (named), not a crash
    with open(path, "rb") as fh:
        for lineno, braw in enumerate(fh, start=1):
            st.lines += 1
            if not braw.strip():
                continue
            try:
                raw = braw.decode("utf-8")
                obj = loads(raw)
            except UnicodeDecodeError as exc:
                err = FormatError(f"not UTF-8 text: byte 0x{braw[exc.start]:02x} at column {exc.start + 1}",
                                  path=path, line=lineno)
                _skip(st, err, skip_bad_lines)
                first = False
                continue
            except (json.JSONDecodeError, RecursionError) as exc:
                msg = f"{exc.msg} (column {exc.colno})" if isinstance(exc, json.JSONDecodeError) else "nested too deeply"
                err = FormatError(f"bad JSON: {msg}", path=path, line=lineno)
                _skip(st, err, skip_bad_lines)
                first = False
                continue
            if first:
                first = False
                if type(obj) is dict and "format" in obj and "targets" not in obj:
                    _check_header(obj, EVENTS_FORMAT, path, lineno)  # a bad header is always fatal
                    st.header = obj
                    continue
            try:
                rec = _fast_check(obj)
            except _Bad:
                err = FormatError(_pydantic_message(obj), path=path, line=lineno)
                _skip(st, err, skip_bad_lines)
                continue
            eid = rec.id
            if eid is not None:
                if eid in seen_ids:
                    err = FormatError(f"field 'id': duplicate event id {eid!r} (ids must be unique within a log)",
                                      path=path, line=lineno)
                    _skip(st, err, skip_bad_lines)
                    continue
                seen_ids.add(eid)
            st.events += 1
            yield rec


def _skip(st: ReadStats, err: FormatError, skip_bad_lines: bool) -> None:
    """A bad line: raised unless ``skip_bad_lines``, else counted (and its message kept)."""
    if not skip_bad_lines:
        raise err from None
    st.skipped += 1
    if len(st.errors) < st.max_errors:
        st.errors.append(str(err))


def read_events(
    path: str | os.PathLike[str], *, skip_bad_lines: bool = False, stats: ReadStats | None = None
) -> list[EventRecord]:
    """All events of a file as a list (see :func:`iter_events`)."""
    return list(iter_events(path, skip_bad_lines=skip_bad_lines, stats=stats))


def event_to_json(record: EventRecord | Mapping[str, Any]) -> str:
    """One canonical JSON line (no trailing newline) for a record; NaN is rejected."""
    d = record.to_dict() if isinstance(record, EventRecord) else dict(record)
    return json.dumps(d, separators=(",", ":"), allow_nan=False, ensure_ascii=False)


def write_events(
    path: str | os.PathLike[str],
    records: Iterable[EventRecord | Mapping[str, Any]],
    *,
    header: bool = True,
) -> int:
    """Validate and write events atomically (temp file + ``os.replace``); return the count.

    Records may be :class:`EventRecord` or plain mappings with the same keys.  An invalid record
    raises :class:`FormatError` naming its (output) line and field; nothing is written then.
    """
    count = 0

    def chunks() -> Iterator[str]:
        nonlocal count
        lineno = 0
        if header:
            lineno += 1
            yield json.dumps({"format": EVENTS_FORMAT, "version": FORMAT_VERSION}) + "\n"
        for rec in records:
            lineno += 1
            obj = rec.to_dict() if isinstance(rec, EventRecord) else dict(rec)
            validate_event(obj, path=path, line=lineno)
            count += 1
            yield event_to_json(obj) + "\n"

    atomic_write_text(path, chunks())
    return count


# --------------------------------------------------------------------------- truth.json


def _load_json(path: str | os.PathLike[str]) -> Any:
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except json.JSONDecodeError as exc:
        raise FormatError(f"bad JSON: {exc.msg} (column {exc.colno})", path=path, line=exc.lineno) from None
    except UnicodeDecodeError as exc:
        raise FormatError(f"not UTF-8 text (byte offset {exc.start})", path=path) from None
    except RecursionError:
        raise FormatError("bad JSON: nested too deeply", path=path) from None


def read_truth(path: str | os.PathLike[str]) -> dict[str, dict[str, int]]:
    """Read ``truth.json``: ``{node: {predicate: 0 | 1}}``; optional top-level ``format``/``version``.

    Header keys are recognised by type (their values are strings / integers, while a node's value
    is always an object), so they never collide with node ids.
    """
    obj = _load_json(path)
    if not isinstance(obj, dict):
        raise FormatError("truth file must be a JSON object {node: {predicate: 0|1}}", path=path)
    header = {k: obj[k] for k in ("format", "version") if k in obj and not isinstance(obj[k], dict)}
    if header:
        _check_header({"format": header.get("format", TRUTH_FORMAT), "version": header.get("version", 1)},
                      TRUTH_FORMAT, path, None)
    out: dict[str, dict[str, int]] = {}
    for node, preds in obj.items():
        if node in header:
            continue
        if not isinstance(preds, dict):
            raise FormatError(f"field '{node}': must be an object {{predicate: 0|1}}", path=path)
        row: dict[str, int] = {}
        for pred, y in preds.items():
            if isinstance(y, bool) or y not in (0, 1) or not isinstance(y, (int, float)):
                raise FormatError(f"field '{node}.{pred}': truth must be 0 or 1, got {y!r}", path=path)
            if not pred:
                raise FormatError(f"field '{node}': empty predicate name", path=path)
            row[pred] = int(y)
        out[str(node)] = row
    return out


def write_truth(path: str | os.PathLike[str], truth: Mapping[str, Mapping[str, int]], *, header: bool = True) -> None:
    """Write ``truth.json`` atomically (nodes and predicates in the given order)."""
    doc: dict[str, Any] = {"format": TRUTH_FORMAT, "version": FORMAT_VERSION} if header else {}
    for node, preds in truth.items():
        if node in ("format", "version") and header:
            raise FormatError(f"node id {node!r} is reserved when a header is written", path=path)
        doc[str(node)] = {str(p): int(y) for p, y in preds.items()}
        if any(y not in (0, 1) for y in doc[str(node)].values()):
            raise FormatError(f"field '{node}': truth values must be 0 or 1", path=path)
    atomic_write_text(path, [json.dumps(doc, separators=(",", ":")), "\n"])


# --------------------------------------------------------------------------- nodes.json


def read_nodes(path: str | os.PathLike[str]) -> NodesFile:
    """Read and validate ``nodes.json``; errors name the node and field."""
    obj = _load_json(path)
    if isinstance(obj, dict) and "format" in obj:
        _check_header({"format": obj.get("format"), "version": obj.get("version", 1)}, NODES_FORMAT, path, None)
    try:
        return NodesFile.model_validate(obj)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"])
        raise FormatError(f"field '{loc}': {err['msg']}", path=path) from None


def node_attributes(info: NodeInfo) -> dict[str, Any]:
    """A node's ``nodes.json`` record as scene-graph node attributes (``bbox`` from bbox_min / bbox_max,
    unset fields left out): what ``SceneGraph.add_node(node, **attrs)`` takes."""
    d = info.model_dump()
    attrs = {k: v for k, v in d.items() if k not in ("bbox_min", "bbox_max") and v is not None}
    attrs["bbox"] = (tuple(info.bbox_min), tuple(info.bbox_max))
    return attrs


def write_nodes(path: str | os.PathLike[str], nodes: NodesFile | Mapping[str, Any]) -> None:
    """Write ``nodes.json`` atomically (validated first)."""
    doc = nodes if isinstance(nodes, NodesFile) else NodesFile.model_validate(nodes)
    atomic_write_text(path, [doc.model_dump_json(exclude_none=False), "\n"])
