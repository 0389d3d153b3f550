"""Columnar binary layout of a :class:`SceneGraphModel`: one uncompressed ``.npz`` (``sgbelief.scene_graph.npz`` v1).

The JSON format (:mod:`sgbelief.graph.persistence`) holds the same information, but writing and
parsing ~200 bytes of JSON per node and per log entry is slow for 10⁶-node maps. Here every
per-node, per-pair and per-entry field is one numpy array (a string column is one NUL-separated
UTF-8 blob), and everything irregular (vocabulary, meta, attribute-column types) sits in a small
JSON ``header``. The layout is documented in ``docs/formats.md``; its parts live in
:mod:`~sgbelief.graph.npz_archive` (the checked container), :mod:`~sgbelief.graph.npz_columns`
(value columns), :mod:`~sgbelief.graph.npz_attributes` (attribute dicts) and
:mod:`~sgbelief.graph.npz_provenance` (the provenance store); this module holds the graph's
nodes, edges and header.

Loading checks index ranges, status codes, finite numbers and Eq. 4 (vectorised) before building
any Python object. Every failure is a :class:`~sgbelief.errors.FormatError` naming the array or
header field.

A loaded graph equals what loading the JSON file of the same graph gives
(``graph_to_dict`` is equal, attributes get the same Python types), and its provenance store
is fully functional (record, retract, compact, queues). It keeps three things JSON does not:
the queues' and the compaction timeline's exact order, ``corroborated_by == []`` and
``remember_compacted``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any, BinaryIO

import networkx as nx
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from sgbelief.graph.atomic import atomic_write_binary
from sgbelief.graph.json_values import jsonable
from sgbelief.graph.loading import REFERENCE_LOADING, GraphLoading
from sgbelief.graph.npz_archive import (
    FORMAT,
    I8,
    U1,
    VERSION,
    NpzArchive,
    check_index,
    gc_paused,
    open_npz,
    write_npz,
    young_collections_only,
)
from sgbelief.graph.npz_attributes import RecordsSpec, decode_records, encode_records
from sgbelief.graph.npz_columns import ColumnSpec, by_address, decode_values, encode_values, json_constant, match_rows
from sgbelief.graph.npz_provenance import read_provenance
from sgbelief.graph.npz_provenance_save import provenance_arrays
from sgbelief.graph.provenance import EntryStatus
from sgbelief.graph.scene_graph import SceneGraphModel

__all__ = ["FORMAT", "VERSION", "save_graph_npz", "load_graph_npz", "graph_to_arrays"]


# ======================================================================== header
class _Counts(BaseModel):
    model_config = ConfigDict(strict=True)
    nodes: int = Field(ge=0)
    edges: int = Field(ge=0)
    pairs: int = Field(ge=0)
    entries: int = Field(ge=0)
    corroborated: int = Field(ge=0)
    corroborating_ids: int = Field(ge=0)
    timeline: int = Field(ge=0)
    quarantine: int = Field(ge=0)
    disagreement: int = Field(ge=0)
    compacted_ids: int = Field(ge=0)


class _Header(BaseModel):
    model_config = ConfigDict(extra="allow", strict=True)
    format: str
    version: int
    created_by: str = ""
    vocabulary: list[str] | None
    clock: int
    meta: dict[str, Any]
    graph_attrs: dict[str, Any]
    prior: list[float] = Field(min_length=2, max_length=2)
    remember_compacted: int = Field(ge=0)
    n_compacted: int = Field(ge=0)
    statuses: list[str]
    predicates: list[str]
    counts: _Counts
    node_ids: ColumnSpec
    node_attrs: RecordsSpec
    edge_keys: ColumnSpec
    edge_attrs: RecordsSpec


def _read_header(arch: NpzArchive) -> _Header:
    raw = arch.read("header", U1, (None,))
    try:
        doc = json.loads(raw.tobytes().decode("utf-8"), parse_constant=json_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise arch.error(f"array 'header': not a JSON text ({type(exc).__name__}: {exc})") from None
    if not isinstance(doc, dict):
        raise arch.error("array 'header': must hold a JSON object")
    if doc.get("format") != FORMAT:
        raise arch.error(f"header field 'format': expected {FORMAT!r}, got {doc.get('format')!r}")
    version = doc.get("version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise arch.error(f"header field 'version': expected a positive integer, got {version!r}")
    if version > VERSION:
        raise arch.error(f"file has {FORMAT} version {version}; this sgbelief reads up to {VERSION}")
    try:
        header = _Header.model_validate(doc)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = ".".join(str(x) for x in first["loc"])
        raise arch.error(f"header field '{loc}': {first['msg']}") from None
    a0, b0 = header.prior
    if not (math.isfinite(a0) and math.isfinite(b0) and a0 > 0 and b0 > 0):
        raise arch.error("header field 'prior': must be two finite numbers > 0")
    known = {s.value for s in EntryStatus}
    for s in header.statuses:
        if s not in known:
            raise arch.error(f"header field 'statuses': unknown status {s!r}")
    for p in header.predicates:
        if not p:
            raise arch.error("header field 'predicates': predicates must be non-empty strings")
    if len(set(header.predicates)) != len(header.predicates):
        raise arch.error("header field 'predicates': duplicate predicate")
    return header


# ======================================================================== saving
class _NodeIndex:
    """Row of a node in the saved node table, with no second hash table over 10⁶ ids. A value
    that *is* one of the node dict's key objects (pairs and edges usually hold those) is found by
    its address alone; any other is looked up in the node dict and the attribute dict found there
    is mapped to its row by address (sorted addresses + searchsorted)."""

    def __init__(self, node_dict: dict[Any, dict[str, Any]]) -> None:
        self.node_dict = node_dict
        self._keys: tuple[np.ndarray, np.ndarray] | None = None
        self._dicts: tuple[np.ndarray, np.ndarray] | None = None

    def rows(self, values: list[Any] | tuple[Any, ...]) -> np.ndarray:
        """Row of each value; -1 for values that are not nodes of the graph."""
        nd = self.node_dict
        if not values or not nd:
            return np.full(len(values), -1, dtype=I8)
        if self._keys is None:
            self._keys = by_address(nd, len(nd))
        out = match_rows(*self._keys, values, len(values))
        miss = np.flatnonzero(out < 0)
        if len(miss):  # equal but distinct objects (or not nodes): through the node dict
            if self._dicts is None:
                self._dicts = by_address(nd.values(), len(nd))
            missing: dict[str, Any] = {}  # never one of the graph's attribute dicts
            others = [values[i] for i in miss.tolist()]
            out[miss] = match_rows(*self._dicts, (nd.get(v, missing) for v in others), len(others))
        return out


def _edges(g: nx.MultiDiGraph) -> list[tuple[Any, Any, Any, dict[str, Any]]]:
    """(source, target, key, attributes) of every edge, in networkx's order (a map of 10⁶ nodes
    without relations is checked for edges in one C pass first)."""
    return [] if nx.is_empty(g) else list(g.edges(keys=True, data=True))


def graph_to_arrays(graph: SceneGraphModel) -> dict[str, np.ndarray]:
    """The arrays of the binary layout (``header`` included). Raises TypeError / ValueError on
    values the format cannot hold (non-finite floats, unserialisable attributes, bad ids)."""
    from sgbelief.version import __version__

    g = graph.nx
    arrays: dict[str, np.ndarray] = {}
    # ---- nodes (iterating the node view with data walks networkx's node dict in C)
    node_dict: dict[Any, dict[str, Any]] = dict(iter(g.nodes(data=True)))
    node_ids = list(node_dict)
    nid_spec, arrs = encode_values(node_ids, lambda i: f"node id {node_ids[i]!r}")
    if nid_spec["kind"] != "str":
        for n in node_ids:
            if isinstance(n, bool) or not isinstance(n, (str, int)):
                raise TypeError(f"node ids must be str or int, got {type(n).__name__} {n!r}")
    arrays.update({f"node_id{s}": a for s, a in arrs.items()})
    node_attrs, arrs = encode_records(list(node_dict.values()), "node", lambda i: f"node {node_ids[i]!r}", True)
    arrays.update(arrs)
    index = _NodeIndex(node_dict)
    # ---- edges
    edges = _edges(g)
    src = index.rows([e[0] for e in edges])
    dst = index.rows([e[1] for e in edges])
    if len(edges) and (src.min() < 0 or dst.min() < 0):  # pragma: no cover - networkx keeps endpoints as nodes
        raise ValueError("an edge endpoint is not a node")
    arrays["edge_source"], arrays["edge_target"] = src, dst
    ekeys = [e[2] for e in edges]
    ekey_spec, arrs = encode_values(ekeys, lambda i: f"edge {edges[i][0]!r}->{edges[i][1]!r} key")
    arrays.update({f"edge_key{s}": a for s, a in arrs.items()})
    edge_attrs, arrs = encode_records([e[3] for e in edges], "edge",
                                      lambda i: f"edge {edges[i][0]!r}->{edges[i][1]!r}", False)
    arrays.update(arrs)
    # ---- the provenance store
    prov_arrays, prov = provenance_arrays(graph.provenance, index.rows)
    arrays.update(prov_arrays)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "created_by": f"sgbelief {__version__}",
        "vocabulary": sorted(graph.vocabulary) if graph.vocabulary is not None else None,
        "clock": int(graph.clock),
        "meta": jsonable(graph.meta, "meta"),
        "graph_attrs": jsonable(dict(g.graph), "graph attributes"),
        **{k: v for k, v in prov.items() if k != "counts"},
        "counts": {"nodes": len(node_ids), "edges": len(edges), **prov["counts"]},
        "node_ids": nid_spec,
        "node_attrs": node_attrs,
        "edge_keys": ekey_spec,
        "edge_attrs": edge_attrs,
    }
    text = json.dumps(header, separators=(",", ":"), allow_nan=False)
    arrays["header"] = np.frombuffer(text.encode("utf-8"), U1)
    return arrays


def save_graph_npz(graph: SceneGraphModel, path: str | Path) -> Path:
    """Write ``graph`` as one uncompressed ``.npz`` atomically (temp file, fsync, rename)."""
    path = Path(path)
    with gc_paused():
        arrays = graph_to_arrays(graph)  # fails before touching disk

    def write(fh: BinaryIO) -> None:
        write_npz(fh, arrays)

    atomic_write_binary(path, write)
    return path


# ======================================================================= loading
def load_graph_npz(path: str | Path, *, graph_type: type[SceneGraphModel] = SceneGraphModel,
                   loading: GraphLoading = REFERENCE_LOADING) -> SceneGraphModel:
    """Read a graph written by :func:`save_graph_npz`; any malformed, truncated, edited or hostile
    file raises FormatError naming the array or header field (and no graph is returned).

    ``graph_type``: the class of the graph returned (made with the file's vocabulary);
    ``loading``: how its provenance store and node table are built (the reference store, by
    default)."""
    with open_npz(Path(path)) as arch, young_collections_only():
        return _load(arch, graph_type, loading)


def _load(arch: NpzArchive, graph_type: type[SceneGraphModel], loading: GraphLoading) -> SceneGraphModel:
    h = _read_header(arch)
    c = h.counts
    n = c.nodes
    # ------------------------------------------------ read and validate every array first
    if h.node_ids.kind not in ("str", "int", "json"):
        raise arch.error("header field 'node_ids.kind': node ids must be stored as str, int or json")
    node_ids = decode_values(arch, "node_id", h.node_ids.model_dump(), n)
    for i, v in enumerate(node_ids if h.node_ids.kind == "json" else ()):
        if isinstance(v, bool) or not isinstance(v, (str, int)):
            raise arch.error(f"array 'node_id' row {i}: node ids must be strings or integers, got {v!r}")
    src = arch.read("edge_source", I8, (c.edges,))
    dst = arch.read("edge_target", I8, (c.edges,))
    check_index(arch, "edge_source", src, n)
    check_index(arch, "edge_target", dst, n)
    edge_keys = decode_values(arch, "edge_key", h.edge_keys.model_dump(), c.edges)
    for i, k in enumerate(edge_keys if h.edge_keys.kind in ("json", "float") else ()):
        if not isinstance(k, (str, int, float, bool, type(None))):
            raise arch.error(f"array 'edge_key' row {i}: edge keys must be scalars, got {k!r}")
    columns = read_provenance(arch, h, node_ids)
    node_attrs = decode_records(arch, "node", h.node_attrs, n, True)
    edge_attrs = decode_records(arch, "edge", h.edge_attrs, c.edges, False)
    arch.check_unused()
    # ------------------------------------------------------------- build the graph
    graph = graph_type(vocabulary=h.vocabulary)
    graph.clock = h.clock
    graph.meta = dict(h.meta)
    g = graph.nx
    g.graph.update(h.graph_attrs)
    loading.add_nodes(g, node_ids, node_attrs)
    if len(g) != n:
        raise arch.error("array 'node_id': duplicate node id")
    if c.edges:
        g.add_edges_from(zip(_pick(node_ids, src), _pick(node_ids, dst), edge_keys, edge_attrs))
    graph.provenance = loading.store_from_columns(columns)
    if len(graph.provenance) != c.pairs:
        raise columns.duplicate_pair_error()
    return graph


def _pick(values: list[Any], rows: np.ndarray) -> Iterable[Any]:
    """``values[i]`` for each row ``i``."""
    return map(values.__getitem__, rows.tolist())
