"""Lossless, versioned, atomic JSON persistence of a :class:`SceneGraphModel`.

File layout (``format: sgbelief.scene_graph``, ``version: 1``)::

    {"format": "sgbelief.scene_graph", "version": 1, "created_by": "sgbelief X.Y.Z",
     "vocabulary": [...] | null, "clock": int, "meta": {...},
     "graph": <networkx node-link data, edges under "edges">,
     "provenance": {"prior": [a0, b0], "pairs": [{"node", "predicate", "alpha", "beta",
                    "entries": [[event_id, t, d_alpha, d_beta, status, stance, corroborated_by, n_folded,
                                 (verdict, confidence)], ...], "fold_summary": {...} (optional)}],
                    "compacted_ids": [...], "n_compacted": int}}

An entry's last two fields, the verdict code (:class:`~sgbelief.graph.provenance_log.EntryVerdict`
or null) and the event's confidence, are present when the operator recorded either (8-field rows,
of older files and of the baselines, load with None).

The queues (revision quarantine Q, disagreement queue Q⊥) are the pending entries of the
provenance log, so they round-trip with it. Loading validates the envelope with pydantic and
checks Eq. 4 of the paper (stored belief = prior + logged increments) for every pair.

:func:`save_graph` / :func:`load_graph` also dispatch to the columnar binary layout of
:mod:`sgbelief.graph.binary` (``.npz``, ``format: sgbelief.scene_graph.npz``) by suffix or
``format=``; JSON stays the default.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from sgbelief.errors import FormatError
from sgbelief.graph.atomic import atomic_write_binary, atomic_write_text, remove_stale_temp_files
from sgbelief.graph.binary import load_graph_npz, save_graph_npz
from sgbelief.graph.json_values import jsonable, restore_node_attr
from sgbelief.graph.loading import REFERENCE_LOADING, GraphLoading
from sgbelief.graph.provenance_json import store_to_dict
from sgbelief.graph.scene_graph import SceneGraphModel

FORMAT = "sgbelief.scene_graph"
VERSION = 1
GRAPH_FILE = "graph.json"
#: file name inside a map directory, by format
GRAPH_FILES = {"json": GRAPH_FILE, "npz": "graph.npz"}
_SUFFIX_FORMAT = {".json": "json", ".npz": "npz"}
_ZIP_MAGIC = b"PK\x03\x04"


class _Envelope(BaseModel):
    model_config = ConfigDict(extra="allow")
    format: Literal["sgbelief.scene_graph"]
    version: int = Field(strict=True)  # "1" (a string) is not a version
    vocabulary: list[str] | None = None
    clock: int = -1
    meta: dict[str, Any] = {}
    graph: dict[str, Any]
    provenance: dict[str, Any]


def _check_format(format: str | None) -> None:
    if format is not None and format not in GRAPH_FILES:
        raise ValueError(f"format must be one of {sorted(GRAPH_FILES)}, got {format!r}")


def resolve_graph_path(path: str | Path, format: str | None = None) -> Path:
    """Where a graph is saved: ``x.json`` / ``x.npz`` stay as they are; anything else is a
    directory holding ``graph.json`` (or ``graph.npz`` with ``format="npz"``)."""
    return _resolve(path, format)[0]


def _resolve(path: str | Path, format: str | None, *, loading: bool = False) -> tuple[Path, str]:
    """(file, format) for a save or load; a file suffix that contradicts ``format`` is an error."""
    _check_format(format)
    p = Path(path)
    by_suffix = _SUFFIX_FORMAT.get(p.suffix)
    if by_suffix is not None:
        if format is not None and format != by_suffix:
            raise ValueError(f"{p}: suffix {p.suffix} does not match format={format!r}")
        return p, by_suffix
    if format is not None:
        return p / GRAPH_FILES[format], format
    if loading:
        found = [fmt for fmt, name in GRAPH_FILES.items() if (p / name).exists()]
        if len(found) > 1:
            raise FormatError(f"both {GRAPH_FILE} and {GRAPH_FILES['npz']} are present; pass format= or the file path",
                              path=p)
        if found:
            return p / GRAPH_FILES[found[0]], found[0]
    return p / GRAPH_FILE, "json"


def graph_to_dict(graph: SceneGraphModel) -> dict[str, Any]:
    g = graph.nx
    nodes = []
    for n, data in g.nodes(data=True):
        entry = {"id": n}
        for k, v in data.items():
            entry[k] = jsonable(v, f"node {n!r} attribute {k!r}")
        nodes.append(entry)
    edges = []
    for u, v, k, data in g.edges(keys=True, data=True):
        entry = {"source": u, "target": v, "key": k}
        for name, val in data.items():
            entry[name] = jsonable(val, f"edge {u!r}->{v!r} attribute {name!r}")
        edges.append(entry)
    from sgbelief.version import __version__

    return {
        "format": FORMAT,
        "version": VERSION,
        "created_by": f"sgbelief {__version__}",
        "vocabulary": sorted(graph.vocabulary) if graph.vocabulary is not None else None,
        "clock": graph.clock,
        "meta": jsonable(graph.meta, "meta"),
        "graph": {"directed": True, "multigraph": True, "graph": dict(g.graph), "nodes": nodes, "edges": edges},
        "provenance": store_to_dict(graph.provenance),
    }


def save_graph(graph: SceneGraphModel, path: str | Path, *, format: str | None = None) -> Path:
    """Serialise first (so an unserialisable attribute fails before touching disk), then write atomically.

    ``format``: ``"json"`` (default) or ``"npz"`` (the binary layout of :mod:`sgbelief.graph.binary`);
    by default a ``.npz`` suffix selects the binary layout.
    """
    target, fmt = _resolve(path, format)
    if fmt == "npz":
        return save_graph_npz(graph, target)
    text = json.dumps(graph_to_dict(graph), separators=(",", ":"), allow_nan=False)
    atomic_write_text(target, text)
    return target


def graph_from_dict(doc: dict[str, Any], *, source: str = "<dict>", graph_type: type[SceneGraphModel] = SceneGraphModel,
                    loading: GraphLoading = REFERENCE_LOADING) -> SceneGraphModel:
    """The graph of a JSON document (:func:`graph_to_dict`); ``graph_type`` / ``loading`` as in
    :func:`load_graph`."""
    try:
        env = _Envelope.model_validate(doc)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = ".".join(str(x) for x in first["loc"])
        raise FormatError(f"field '{loc}': {first['msg']}", path=source) from exc
    if env.version > VERSION or env.version < 1:
        raise FormatError(f"field 'version': file has schema version {env.version}; this sgbelief reads 1..{VERSION}",
                          path=source)
    graph = graph_type(vocabulary=env.vocabulary)
    graph.clock = env.clock
    graph.meta = dict(env.meta)
    try:
        g = graph.nx
        g.graph.update(env.graph.get("graph", {}))
        for i, node in enumerate(env.graph["nodes"]):
            attrs = dict(node)
            n = attrs.pop("id")
            if isinstance(n, bool) or not isinstance(n, (str, int)):
                raise FormatError(f"field 'graph.nodes[{i}].id' must be a string or integer", path=source)
            if n in g:  # a second entry would silently merge into (and drop) the first
                raise FormatError(f"field 'graph.nodes[{i}].id': duplicate node id {n!r}", path=source)
            for key in ("centroid", "bbox"):
                if key in attrs:
                    attrs[key] = restore_node_attr(key, attrs[key])
            g.add_node(n, **attrs)
        for i, edge in enumerate(env.graph["edges"]):
            attrs = dict(edge)
            u, v, k = attrs.pop("source"), attrs.pop("target"), attrs.pop("key")
            if u not in g or v not in g:
                raise FormatError(f"field 'graph.edges[{i}]' refers to an unknown node", path=source)
            g.add_edge(u, v, key=k, **attrs)
    except FormatError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"field 'graph': malformed node-link data ({type(exc).__name__}: {exc})", path=source) from exc
    try:
        graph.provenance = loading.store_from_dict(env.provenance)
    except FormatError as exc:
        raise FormatError(str(exc), path=source) from exc
    for node, _pred in graph.provenance.pairs():
        if node not in g:
            raise FormatError(f"provenance refers to node {node!r} that the graph does not contain", path=source)
    return graph


def load_graph(path: str | Path, *, format: str | None = None, graph_type: type[SceneGraphModel] = SceneGraphModel,
               loading: GraphLoading = REFERENCE_LOADING) -> SceneGraphModel:
    """Read a saved graph; truncated, edited or hostile files raise FormatError (line / array and field).

    A directory holds ``graph.json`` or ``graph.npz``; a file's suffix selects its format unless
    ``format`` is given. ``graph_type``: the class of the graph returned; ``loading``: how its
    provenance store and node table are built (:mod:`sgbelief.graph.loading`; the reference
    store by default).
    """
    target, fmt = _resolve(path, format, loading=True)
    if not target.exists():
        raise FileNotFoundError(f"no saved scene graph at {target}")
    if fmt == "npz":
        return load_graph_npz(target, graph_type=graph_type, loading=loading)
    with open(target, "rb") as fh:
        if fh.read(4) == _ZIP_MAGIC:
            raise FormatError("this is a binary (npz) scene graph, not JSON; name it .npz or pass format='npz'",
                              path=target)
    try:
        with open(target, encoding="utf-8") as fh:
            doc = json.load(fh)
    except json.JSONDecodeError as exc:
        raise FormatError(f"invalid JSON: {exc.msg} (column {exc.colno})", path=target, line=exc.lineno) from exc
    except UnicodeDecodeError as exc:
        raise FormatError(f"not UTF-8 text: {exc}", path=target) from exc
    if not isinstance(doc, dict):
        raise FormatError("top level must be a JSON object", path=target)
    return graph_from_dict(doc, source=str(target), graph_type=graph_type, loading=loading)


__all__ = [
    "save_graph",
    "load_graph",
    "graph_to_dict",
    "graph_from_dict",
    "atomic_write_text",
    "atomic_write_binary",
    "remove_stale_temp_files",
    "resolve_graph_path",
    "restore_node_attr",
]
