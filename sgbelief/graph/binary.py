"""Columnar binary layout of a :class:`SceneGraph`: one uncompressed ``.npz`` (``sgbelief.scene_graph.npz`` v1).

The JSON format (:mod:`sgbelief.graph.persistence`) holds the same information, but writing and
parsing ~200 bytes of JSON per node and per log entry is slow for 10⁶-node maps. Here every
per-node, per-pair and per-entry field is one numpy array (a string column is one NUL-separated
UTF-8 blob), and everything irregular (vocabulary, meta, attribute-column types) sits in a small
JSON ``header``. The layout is documented in ``docs/formats.md``.

Loading never unpickles (``np.load(..., allow_pickle=False)``) and checks, before any array's
bytes are read, that its dtype and shape are the ones the header implies and that its zip
member is stored uncompressed and fits the file; then it checks index ranges, status codes,
finite numbers and Eq. 5 (vectorised) before building any Python object. Every failure is a
:class:`~sgbelief.errors.FormatError` naming the array or header field.

A loaded graph equals what loading the JSON file of the same graph gives
(``graph_to_dict`` is equal, attributes get the same Python types), and its provenance store
is fully functional (record, retract, compact, queues). It keeps three things JSON does not:
the queues' and the compaction timeline's exact order, ``corroborated_by == []`` and
``remember_compacted``.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
import zlib
from collections import deque
from collections.abc import Callable, Iterable
from functools import partial
from itertools import chain, islice, repeat
from operator import attrgetter, is_, is_not, itemgetter
from pathlib import Path
from typing import Any, BinaryIO

import networkx as nx
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from sgbelief._fast.gc import gc_paused, young_collections_only
from sgbelief.errors import FormatError
from sgbelief.graph.persistence import _jsonable, atomic_write_binary, restore_node_attr
from sgbelief.graph.provenance import (
    COUNTED,
    PENDING,
    EntryStatus,
    ProvenanceEntry,
    ProvenanceStore,
    _PairLog,
    index_event,
)
from sgbelief.graph.scene_graph import SceneGraph

FORMAT = "sgbelief.scene_graph.npz"
VERSION = 1

_F8 = np.dtype("<f8")
_I8 = np.dtype("<i8")
_I4 = np.dtype("<i4")
_I1 = np.dtype("|i1")
_U1 = np.dtype("|u1")
_B1 = np.dtype("|b1")
#: node attributes the JSON loader turns into tuples of float (see ``restore_node_attr``)
_SPECIAL_DEPTH = {"centroid": 1, "bbox": 2}
_FLOAT_TYPES = frozenset({float, np.float64})
_SEP = "\x00"
#: rows per pass when walking millions of Python objects: the later passes over a chunk hit the cache
_CHUNK = 8192

__all__ = ["FORMAT", "VERSION", "save_graph_npz", "load_graph_npz", "graph_to_arrays"]


# ====================================================================== strings
def _encode_strings(values: list[str] | tuple[str, ...], where: Callable[[int], str]) -> dict[str, np.ndarray]:
    """``.text``: UTF-8 of the strings joined by NUL. Only when a string itself holds a NUL is a
    ``.lengths`` array (UTF-8 byte length of each string) added. Raises TypeError on a non-str."""
    try:
        text = _SEP.join(values)
    except TypeError:
        i = next(i for i, v in enumerate(values) if not isinstance(v, str))
        raise TypeError(f"{where(i)}: expected a string, got {type(values[i]).__name__}") from None
    data = np.frombuffer(text.encode("utf-8", "surrogatepass"), _U1)
    if not values or text.count(_SEP) == len(values) - 1:
        return {".text": data}
    return {".text": data, ".lengths": np.fromiter((len(v.encode("utf-8", "surrogatepass")) for v in values),
                                                    _I8, len(values))}


def _decode_strings(data: np.ndarray, lengths: np.ndarray | None, rows: int, err: Callable[[str], FormatError]
                    ) -> list[str]:
    """Inverse of :func:`_encode_strings`; checks the text is UTF-8 and holds exactly ``rows`` strings."""
    return _checked_strings(data, lengths, rows, err)()


def _checked_strings(data: np.ndarray, lengths: np.ndarray | None, rows: int, err: Callable[[str], FormatError]
                     ) -> Callable[[], list[str]]:
    """:func:`_decode_strings` with the split left to the caller: every check is made now, the
    returned callable (picklable) makes the list of strings."""
    raw = data.tobytes()
    try:
        text = raw.decode("utf-8", "surrogatepass")
    except UnicodeDecodeError as exc:
        raise err(f"text is not UTF-8 ({exc.reason} at byte {exc.start})") from None
    if rows == 0:
        if raw:
            raise err("text must be empty when there are no strings")
        return list
    if lengths is None:
        if text.count(_SEP) != rows - 1:
            raise err(f"expected {rows} NUL-separated strings, found {text.count(_SEP) + 1}")
        return partial(str.split, text, _SEP)
    if int(lengths.min()) < 0 or int(lengths.max()) > len(raw):
        raise err("string lengths out of range")
    ends = np.cumsum(lengths + 1) - 1  # separator after each string; the last "separator" is the end
    if int(ends[-1]) != len(raw) or any(raw[e] != 0 for e in ends[:-1].tolist()):
        raise err("string lengths do not match the NUL separators in the text")
    values = [raw[a:b].decode("utf-8", "surrogatepass") for a, b in zip((ends - lengths).tolist(), ends.tolist())]
    return partial(list, values)


def _read_strings(arch: _Archive, name: str, rows: int) -> list[str]:
    """A string column: ``<name>.text`` and, when present, ``<name>.lengths``."""
    return _read_strings_later(arch, name, rows)()


def _read_strings_later(arch: _Archive, name: str, rows: int) -> Callable[[], list[str]]:
    """:func:`_read_strings`, checked now, split when the returned callable is called."""
    data = arch.read(name + ".text", _U1, (None,))
    lengths = arch.read(name + ".lengths", _I8, (rows,)) if arch.has(name + ".lengths") else None
    return _checked_strings(data, lengths, rows, lambda msg: arch.error(f"array '{name}.text': {msg}"))


# ================================================================ value columns
# A value column holds one Python value per row. Its header spec {"kind", "shape"} says how:
#   str  -> <name>.text / <name>.lengths         int  -> <name> <i8      bool -> <name> |b1
#   float-> <name> <f8 of shape (rows, *shape)   json -> <name>.text / .lengths, one JSON text per row
def _float_chunk(values: list[Any] | tuple[Any, ...], depth: int, exact: bool) -> tuple[list[int], np.ndarray] | None:
    """:func:`_float_block` of one chunk of rows."""
    shape: list[int] = []
    level: Any = values
    for d in range(depth):
        if exact and not set(map(type, level)) <= {tuple, list}:
            return None
        try:
            lens = set(map(len, level))
        except TypeError:
            return None
        if len(lens) > 1:
            return None
        shape.append(lens.pop() if lens else 0)
        if d < depth - 1:
            level = list(chain.from_iterable(level))
    if exact and not set(map(type, chain.from_iterable(level))) <= _FLOAT_TYPES:
        return None
    try:
        flat = np.fromiter(chain.from_iterable(level), _F8, len(values) * math.prod(shape))
    except (TypeError, ValueError, OverflowError):
        return None
    return shape, flat


def _float_block(values: list[Any] | tuple[Any, ...], depth: int, exact: bool) -> tuple[list[int], np.ndarray] | None:
    """(shape, flat float64 array) when every value is a same-shaped nest (``depth`` levels) of
    sequences of numbers. ``exact``: tuples/lists of exactly ``float`` (other numbers must stay
    what they are); otherwise anything that ``float()`` converts, iterated the way the JSON loader
    iterates ``centroid`` / ``bbox`` (which load as floats either way). Works in chunks of rows,
    so the several passes over a chunk's objects hit the cache."""
    n = len(values)
    first = _float_chunk(values[:_CHUNK], depth, exact)
    if first is None or n <= _CHUNK:
        return first
    shape, head = first
    width = math.prod(shape)
    flat = np.empty(n * width, dtype=_F8)
    flat[:len(head)] = head
    for a in range(_CHUNK, n, _CHUNK):
        got = _float_chunk(values[a:a + _CHUNK], depth, exact)
        if got is None or got[0] != shape:
            return None
        flat[a * width:a * width + len(got[1])] = got[1]
    return shape, flat


def _encode_values(values: list[Any], where: Callable[[int], str], special: str | None = None
                   ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Pick the tightest kind for a column and encode it; anything irregular becomes per-row JSON."""
    try:
        return {"kind": "str"}, _encode_strings(values, where)
    except TypeError:
        pass
    types = set(map(type, values))
    if types == {bool}:
        return {"kind": "bool"}, {"": np.array(values, dtype=_B1)}
    if types == {int}:
        try:
            return {"kind": "int"}, {"": np.array(values, dtype=_I8)}
        except OverflowError:
            pass
    block = None
    if types <= _FLOAT_TYPES:
        block = [], np.array(values, dtype=_F8)
    elif special is not None and types <= {tuple, list}:
        block = _float_block(values, _SPECIAL_DEPTH[special], exact=False)
    elif types <= {tuple, list}:
        block = _float_block(values, 1, exact=True) or _float_block(values, 2, exact=True)
    if block is not None:
        shape, flat = block
        arr = flat.reshape(len(values), *shape)
        finite = np.isfinite(flat)
        if not finite.all():
            i = int(np.flatnonzero(~finite)[0]) // max(math.prod(shape), 1)
            raise ValueError(f"{where(i)}: non-finite float in {values[i]!r} cannot be saved")
        return {"kind": "float", "shape": shape}, {"": arr}
    texts = [json.dumps(_jsonable(v, where(i)), separators=(",", ":"), allow_nan=False) for i, v in enumerate(values)]
    return {"kind": "json"}, _encode_strings(texts, where)


def _value_array(spec: dict[str, Any], rows: int) -> tuple[np.dtype, tuple[int, ...]]:
    """(dtype, shape) of a numeric value column of ``rows`` rows."""
    kind = spec["kind"]
    if kind == "float":
        return _F8, (rows, *spec.get("shape", []))
    return (_I8 if kind == "int" else _B1), (rows,)


def _json_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed")


_SAMPLE = 1024  #: rows sampled to guess whether a numeric column has few distinct values
_FEW = 64  #: at most this many distinct values in the sample: try sharing Python objects


def _pylist(arr: np.ndarray) -> list[Any]:
    """``arr.tolist()`` of a 1-d int64 / float64 array, except that when the column holds only a few
    distinct values (a constant, unit weights, flags) equal values share one Python object: far
    fewer allocations, same values. Values are compared bit for bit (``-0.0`` stays ``-0.0``)."""
    n = len(arr)
    if n < 4 * _SAMPLE or arr.dtype not in (_F8, _I8):
        return arr.tolist()
    bits = arr.view(_I8)
    table = np.unique(bits[np.arange(_SAMPLE, dtype=np.uint64) * np.uint64(2654435761) % np.uint64(n)])
    if len(table) > _FEW:
        return arr.tolist()
    pos = np.searchsorted(table, bits)
    np.minimum(pos, len(table) - 1, out=pos)
    if not np.array_equal(table[pos], bits):  # a value the sample missed: no sharing
        return arr.tolist()
    objs = np.fromiter(table.view(arr.dtype).tolist(), object, len(table))
    return objs[pos].tolist()


def _float_tuples(arr: np.ndarray) -> list[Any]:
    """Rows of a (rows, *shape) float array as nested tuples (what the JSON loader makes of
    ``centroid`` / ``bbox``), built column by column so that constant components share one float."""
    if arr.ndim == 1:
        return _pylist(arr)
    return list(zip(*(_float_tuples(arr[:, i]) for i in range(arr.shape[1]))))


def _decode_values(arch: _Archive, name: str, spec: dict[str, Any], rows: int, special: str | None = None
                   ) -> list[Any]:
    """Read a value column back as Python values of the types a JSON round trip gives."""
    kind = spec["kind"]
    if kind in ("str", "json"):
        values = _read_strings(arch, name, rows)
        if kind == "json":
            out = []
            for i, text in enumerate(values):
                try:
                    out.append(json.loads(text, parse_constant=_json_constant))
                except (ValueError, RecursionError) as exc:
                    raise arch.error(f"array '{name}' row {i}: bad JSON value ({type(exc).__name__}: {exc})"
                                     ) from None
            values = out
    elif kind == "float":
        arr = arch.read(name, *_value_array(spec, rows))
        finite = np.isfinite(arr.reshape(rows, -1)).all(axis=1) if arr.size else np.ones(rows, dtype=bool)
        if not finite.all():
            raise arch.error(f"array '{name}': non-finite value at row {int(np.flatnonzero(~finite)[0])}")
        shape = list(arr.shape[1:])
        if special is not None and len(shape) == _SPECIAL_DEPTH[special] and 0 not in shape:
            return _float_tuples(arr)
        values = _pylist(arr) if not shape else arr.tolist()
    else:
        arr = arch.read(name, *_value_array(spec, rows))
        values = _pylist(arr) if kind == "int" else arr.tolist()
    if special is not None:
        try:
            values = [restore_node_attr(special, v) for v in values]
        except (TypeError, ValueError) as exc:
            raise arch.error(f"array '{name}': {special} values must be nested sequences of numbers ({exc})") from None
    return values


# ============================================================ attribute records
# Attribute dicts (of nodes, of edges) are stored as key-set patterns: ``<prefix>_pattern`` gives
# each row's pattern, the header lists each pattern's keys, and key j's values (rows that have
# it, in row order) are the value column ``<prefix>_attr.<j>``. Dicts come back with the keys in
# their pattern's order (dict equality does not depend on key order).
def _encode_records(dicts: list[dict[str, Any]], prefix: str, what: Callable[[int], str], special: bool
                    ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    n = len(dicts)
    keys: list[Any] = list(dicts[0]) if n else []
    columns: list[list[Any]] = []
    uniform = False
    if n:  # one key set (the usual case): one list per key, no per-row pattern bookkeeping
        try:
            getters = [itemgetter(k) for k in keys]
            columns = [[] for _ in keys]
            lens: set[int] = set()
            for a in range(0, n, _CHUNK):  # chunk by chunk: the dicts stay in cache across the keys
                chunk = dicts[a:a + _CHUNK]
                lens.update(map(len, chunk))
                for col, get in zip(columns, getters):
                    col += map(get, chunk)
            uniform = lens == {len(keys)}
        except KeyError:
            pass
    if uniform:
        codes = np.zeros(n, dtype=_I4)
        patterns = [list(range(len(keys)))]
        holders_all = True
    else:
        pats = list(map(frozenset, dicts))
        n_distinct = len(set(pats))
        first_row: dict[frozenset[Any], int] = {}
        for i, p in enumerate(pats):
            if p not in first_row:
                first_row[p] = i
                if len(first_row) == n_distinct:
                    break
        uniq = list(first_row)
        keys = list(dict.fromkeys(chain.from_iterable(dicts[first_row[p]] for p in uniq)))
        index = {p: i for i, p in enumerate(uniq)}
        codes = np.fromiter(map(index.__getitem__, pats), _I4, n)
        key_index = {k: j for j, k in enumerate(keys)}
        patterns = [[key_index[k] for k in dicts[first_row[p]]] for p in uniq]
        holders_all = False
    for k in keys:
        if not isinstance(k, str):
            row = next(i for i, d in enumerate(dicts) if k in d)
            raise TypeError(f"{what(row)}: attribute name {k!r} is not a string")
    arrays: dict[str, np.ndarray] = {f"{prefix}_pattern": codes}
    specs = []
    for j, key in enumerate(keys):
        if holders_all:
            vals = columns[j]
            rows_of: Callable[[int], int] = int
        else:
            holders = [p for p, pat in enumerate(patterns) if j in pat]
            if len(holders) == len(patterns):
                vals = [d[key] for d in dicts]
                rows_of = int
            else:
                vals = [d[key] for d in dicts if key in d]
                where_rows = np.flatnonzero(np.isin(codes, holders))
                rows_of = lambda r, w=where_rows: int(w[r])  # noqa: E731
        spec, arrs = _encode_values(vals, lambda r, k=key, f=rows_of: f"{what(f(r))} attribute {k!r}",
                                    key if special and key in _SPECIAL_DEPTH else None)
        specs.append({"key": key, **spec})
        arrays.update({f"{prefix}_attr.{j}{suffix}": a for suffix, a in arrs.items()})
    return {"columns": specs, "patterns": patterns}, arrays


def _make_dicts(keys: list[str], cols: list[list[Any]], count: int) -> list[dict[str, Any]]:
    """One dict per row, keys in order (dict displays for the common small widths are ~2x faster)."""
    w = len(keys)
    if w == 0:
        return [{} for _ in range(count)]
    if w == 1:
        (k0,) = keys
        return [{k0: a} for a in cols[0]]
    if w == 2:
        k0, k1 = keys
        return [{k0: a, k1: b} for a, b in zip(*cols)]
    if w == 3:
        k0, k1, k2 = keys
        return [{k0: a, k1: b, k2: c} for a, b, c in zip(*cols)]
    if w == 4:
        k0, k1, k2, k3 = keys
        return [{k0: a, k1: b, k2: c, k3: d} for a, b, c, d in zip(*cols)]
    return [dict(zip(keys, row)) for row in zip(*cols)]


def _decode_records(arch: _Archive, prefix: str, spec: _Records, n: int, special: bool) -> list[dict[str, Any]]:
    """The attribute dicts, in row order."""
    codes = arch.read(f"{prefix}_pattern", _I4, (n,))
    n_pat, n_keys = len(spec.patterns), len(spec.columns)
    if n and (int(codes.min()) < 0 or int(codes.max()) >= n_pat):
        raise arch.error(f"array '{prefix}_pattern': pattern code out of range [0, {n_pat})")
    for p, pat in enumerate(spec.patterns):
        if len(set(pat)) != len(pat) or any(not 0 <= j < n_keys for j in pat):
            raise arch.error(f"header field '{prefix}_attrs.patterns[{p}]': key indices must be distinct and in range")
    names = [c.key for c in spec.columns]
    if len(set(names)) != len(names) or any(not isinstance(k, str) for k in names):
        raise arch.error(f"header field '{prefix}_attrs.columns': attribute names must be distinct strings")
    per_pattern = np.bincount(codes, minlength=n_pat) if n else np.zeros(n_pat, dtype=np.int64)
    holders = [[p for p, pat in enumerate(spec.patterns) if j in pat] for j in range(n_keys)]
    values = []
    for j, col in enumerate(spec.columns):
        rows = int(per_pattern[holders[j]].sum())
        sp = col.key if special and col.key in _SPECIAL_DEPTH else None
        values.append(_decode_values(arch, f"{prefix}_attr.{j}", col.model_dump(), rows, sp))
    used = [p for p in range(n_pat) if per_pattern[p]]
    if len(used) == 1:
        pat = spec.patterns[used[0]]
        return _make_dicts([names[j] for j in pat], [values[j] for j in pat], n)
    out: list[Any] = [None] * n
    ranks: dict[int, np.ndarray] = {}
    for p in used:
        rows_p = np.flatnonzero(codes == p)
        cols = []
        for j in spec.patterns[p]:
            if len(holders[j]) == 1:
                cols.append(values[j])
                continue
            if j not in ranks:
                ranks[j] = np.cumsum(np.isin(codes, holders[j])) - 1
            vals = values[j]
            cols.append([vals[i] for i in ranks[j][rows_p].tolist()])
        for i, d in zip(rows_p.tolist(), _make_dicts([names[j] for j in spec.patterns[p]], cols, len(rows_p))):
            out[i] = d
    return out


# ======================================================================== header
class _Column(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    kind: str = Field(pattern="^(str|int|float|bool|json)$")
    shape: list[int] = []
    key: str | None = None


class _Records(BaseModel):
    model_config = ConfigDict(strict=True)
    columns: list[_Column]
    patterns: list[list[int]]


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
    node_ids: _Column
    node_attrs: _Records
    edge_keys: _Column
    edge_attrs: _Records


# ======================================================================== saving
def _by_address(objs: Iterable[Any], n: int) -> tuple[np.ndarray, np.ndarray]:
    """(sorted addresses, row of each) of ``n`` objects."""
    ids = np.fromiter(map(id, objs), np.uint64, n)
    order = np.argsort(ids)
    return ids[order], order


def _match(sorted_ids: np.ndarray, order: np.ndarray, objs: Iterable[Any], n: int) -> np.ndarray:
    """Row of each object found (by address) among the sorted ones, -1 where none is."""
    vid = np.fromiter(map(id, objs), np.uint64, n)
    pos = np.minimum(np.searchsorted(sorted_ids, vid), len(sorted_ids) - 1)
    hit = sorted_ids[pos] == vid
    return np.where(hit, order[pos], -1).astype(_I8)


class _NodeIndex:
    """Row of a node in the saved node table, with no second hash table over 10⁶ ids. A value
    that *is* one of the node dict's key objects (pairs and edges usually hold those) is found by
    its address alone; any other is looked up in the graph's own node dict and the attribute dict
    found there is mapped to its row by address (sorted addresses + searchsorted)."""

    def __init__(self, node_dict: dict[Any, dict[str, Any]]) -> None:
        self.node_dict = node_dict
        self._keys: tuple[np.ndarray, np.ndarray] | None = None
        self._dicts: tuple[np.ndarray, np.ndarray] | None = None

    def rows(self, values: list[Any] | tuple[Any, ...]) -> np.ndarray:
        """Row of each value; -1 for values that are not nodes of the graph."""
        nd = self.node_dict
        if not values or not nd:
            return np.full(len(values), -1, dtype=_I8)
        if self._keys is None:
            self._keys = _by_address(nd, len(nd))
        out = _match(*self._keys, values, len(values))
        miss = np.flatnonzero(out < 0)
        if len(miss):  # equal but distinct objects (or not nodes): through the node dict
            if self._dicts is None:
                self._dicts = _by_address(nd.values(), len(nd))
            missing: dict[str, Any] = {}  # never one of the graph's attribute dicts
            others = [values[i] for i in miss.tolist()]
            out[miss] = _match(*self._dicts, map(nd.get, others, repeat(missing)), len(others))
        return out


def _distinct_codes(values: list[Any] | tuple[Any, ...]) -> tuple[np.ndarray, list[Any]]:
    """(code of each value, distinct values in first-appearance order). Values are grouped by
    address first (predicates are usually a handful of shared string objects), then by equality."""
    ids = np.fromiter(map(id, values), np.uint64, len(values))
    _uid, first, inverse = np.unique(ids, return_index=True, return_inverse=True)
    objs = [values[i] for i in first.tolist()]
    distinct = list(dict.fromkeys(values[i] for i in np.sort(first).tolist()))
    code_of = {v: i for i, v in enumerate(distinct)}
    obj_code = np.fromiter(map(code_of.__getitem__, objs), _I8, len(objs))
    return obj_code[inverse.reshape(-1)], distinct


def _positions(objs: Iterable[Any], sorted_ids: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Index in the flat entry list of each object (by identity); objects not in it are dropped."""
    ids = np.fromiter(map(id, objs), np.uint64)
    if not len(sorted_ids) or not len(ids):
        return np.zeros(0, dtype=_I8)
    pos = np.minimum(np.searchsorted(sorted_ids, ids), len(sorted_ids) - 1)
    return order[pos[sorted_ids[pos] == ids]].astype(_I8)


def graph_to_arrays(graph: SceneGraph) -> dict[str, np.ndarray]:
    """The arrays of the binary layout (``header`` included). Raises TypeError / ValueError on
    values the format cannot hold (non-finite floats, unserialisable attributes, bad ids)."""
    from sgbelief import __version__

    g = graph.nx
    prov = graph.provenance
    prov.materialize()  # the layout stores entries, the event index and the timeline
    arrays: dict[str, np.ndarray] = {}
    # ---- nodes
    node_ids = list(g._node)
    nid_spec, arrs = _encode_values(node_ids, lambda i: f"node id {node_ids[i]!r}")
    if nid_spec["kind"] != "str":
        for n in node_ids:
            if isinstance(n, bool) or not isinstance(n, (str, int)):
                raise TypeError(f"node ids must be str or int, got {type(n).__name__} {n!r}")
    arrays.update({f"node_id{s}": a for s, a in arrs.items()})
    node_attrs, arrs = _encode_records(list(g._node.values()), "node", lambda i: f"node {node_ids[i]!r}", True)
    arrays.update(arrs)
    index = _NodeIndex(g._node)
    # ---- edges (scanning 10⁶ empty adjacency dicts in C first)
    edges = ([(u, v, k, d) for u, nbrs in g._succ.items() if nbrs for v, kd in nbrs.items() for k, d in kd.items()]
             if any(g._succ.values()) else [])
    src = index.rows([e[0] for e in edges])
    dst = index.rows([e[1] for e in edges])
    if len(edges) and (src.min() < 0 or dst.min() < 0):  # pragma: no cover - networkx keeps endpoints as nodes
        raise ValueError("an edge endpoint is not a node")
    arrays["edge_source"], arrays["edge_target"] = src, dst
    ekeys = [e[2] for e in edges]
    ekey_spec, arrs = _encode_values(ekeys, lambda i: f"edge {edges[i][0]!r}->{edges[i][1]!r} key")
    arrays.update({f"edge_key{s}": a for s, a in arrs.items()})
    edge_attrs, arrs = _encode_records([e[3] for e in edges], "edge",
                                       lambda i: f"edge {edges[i][0]!r}->{edges[i][1]!r}", False)
    arrays.update(arrs)
    # ---- pairs
    keys = list(prov._pairs)
    logs = list(prov._pairs.values())
    n_pairs = len(keys)
    pair_nodes, pair_preds = tuple(map(itemgetter(0), keys)), tuple(map(itemgetter(1), keys))
    pair_node = index.rows(pair_nodes)
    if n_pairs and pair_node.min() < 0:
        bad = pair_nodes[int(np.flatnonzero(pair_node < 0)[0])]
        raise ValueError(f"provenance refers to node {bad!r} that the graph does not contain")
    arrays["pair_node"] = pair_node
    pred_code, pred_names = _distinct_codes(pair_preds)
    for p in pred_names:
        if not isinstance(p, str) or not p:
            raise ValueError(f"provenance predicate {p!r} must be a non-empty string")
    arrays["pair_predicate"] = pred_code.astype(_I4)
    alpha, beta, lengths = np.empty(n_pairs, _F8), np.empty(n_pairs, _F8), np.empty(n_pairs, _I8)
    flat: list[ProvenanceEntry] = []  # every entry, grouped by pair in log order
    for a in range(0, n_pairs, _CHUNK):
        chunk = logs[a:a + _CHUNK]
        b = a + len(chunk)
        alpha[a:b] = np.fromiter(map(attrgetter("alpha"), chunk), _F8, b - a)
        beta[a:b] = np.fromiter(map(attrgetter("beta"), chunk), _F8, b - a)
        entry_lists = list(map(attrgetter("entries"), chunk))
        lengths[a:b] = np.fromiter(map(len, entry_lists), _I8, b - a)
        flat += chain.from_iterable(entry_lists)
    arrays["pair_alpha"], arrays["pair_beta"], arrays["pair_length"] = alpha, beta, lengths
    bad = ~(np.isfinite(arrays["pair_alpha"]) & np.isfinite(arrays["pair_beta"]))
    if bad.any():
        raise ValueError(f"belief of {keys[int(np.flatnonzero(bad)[0])]!r} is not finite")
    # ---- entries, in the order of ``flat``
    m = len(flat)
    pair_of = lambda i: keys[int(np.searchsorted(np.cumsum(lengths), i, side="right"))]  # noqa: E731
    # chunk by chunk, so that the eight attribute passes over a chunk's entries hit the cache
    t_arr, stance, n_folded = np.empty(m, _I8), np.empty(m, _I1), np.empty(m, _I8)
    da, db = np.empty(m, _F8), np.empty(m, _F8)
    status_c: list[Any] = []
    eid_c: list[Any] = []
    corr_c: list[Any] = []
    get = attrgetter("t"), attrgetter("stance"), attrgetter("n_folded"), attrgetter("d_alpha"), attrgetter("d_beta")
    for a in range(0, m, _CHUNK):
        chunk = flat[a:a + _CHUNK]
        b, k = a + len(chunk), len(chunk)
        try:
            t_arr[a:b] = np.fromiter(map(get[0], chunk), _I8, k)
            stance[a:b] = np.fromiter(map(get[1], chunk), _I1, k)
            n_folded[a:b] = np.fromiter(map(get[2], chunk), _I8, k)
        except (TypeError, ValueError, OverflowError) as exc:
            raise ValueError(f"provenance entry t / n_folded must be 64-bit integers and stance in [-128, 127] "
                             f"({exc})") from None
        da[a:b] = np.fromiter(map(get[3], chunk), _F8, k)
        db[a:b] = np.fromiter(map(get[4], chunk), _F8, k)
        status_c += map(attrgetter("status"), chunk)
        eid_c += map(attrgetter("event_id"), chunk)
        corr_c += map(attrgetter("corroborated_by"), chunk)
    arrays["entry_t"], arrays["entry_stance"], arrays["entry_n_folded"] = t_arr, stance, n_folded
    arrays["entry_d_alpha"], arrays["entry_d_beta"] = da, db
    bad = ~(np.isfinite(da) & np.isfinite(db))
    if bad.any():
        raise ValueError(f"provenance entry of {pair_of(int(np.flatnonzero(bad)[0]))!r}: increments must be finite")
    statuses = list(EntryStatus)
    status_code = {id(s): i for i, s in enumerate(statuses)}
    try:
        status = np.fromiter(map(status_code.__getitem__, map(id, status_c)), _U1, m)
    except KeyError:
        i = next(i for i, s in enumerate(status_c) if id(s) not in status_code)
        raise ValueError(f"provenance entry of {pair_of(i)!r}: status {status_c[i]!r} is not an EntryStatus") from None
    arrays["entry_status"] = status
    null = np.fromiter(map(is_, eid_c, repeat(None)), _B1, m)
    arrays["entry_event_null"] = null
    eids = ["" if e is None else e for e in eid_c] if null.any() else eid_c
    arrays.update({f"entry_event{s}": a
                   for s, a in _encode_strings(eids, lambda i: f"event id of the entry of {pair_of(i)!r}").items()})
    cidx = np.flatnonzero(np.fromiter(map(is_not, corr_c, repeat(None)), _B1, m)).astype(_I8)
    clists = [list(corr_c[i]) for i in cidx.tolist()]
    arrays["corroborated_entry"] = cidx
    arrays["corroborated_length"] = np.fromiter(map(len, clists), _I8, len(clists))
    cids = list(chain.from_iterable(clists))
    arrays.update({f"corroborated_by{s}": a
                   for s, a in _encode_strings(cids, lambda i: "corroborated_by event id").items()})
    # ---- queues and compaction timeline, as entry indices (identity lookup; dead entries drop out)
    flat_ids = np.fromiter(map(id, flat), np.uint64, m)
    order = np.argsort(flat_ids)
    sorted_ids = flat_ids[order]
    arrays["timeline"] = _positions(prov._timeline, sorted_ids, order)
    q = _positions(prov.quarantine, sorted_ids, order)
    arrays["quarantine"] = q[status[q] == statuses.index(EntryStatus.QUARANTINED)]
    d = _positions(prov.disagreement, sorted_ids, order)
    arrays["disagreement"] = d[status[d] == statuses.index(EntryStatus.REFUSED)]
    compacted = list(prov._compacted_order)
    arrays.update({f"compacted_ids{s}": a
                   for s, a in _encode_strings(compacted, lambda i: "compacted event id").items()})
    header = {
        "format": FORMAT,
        "version": VERSION,
        "created_by": f"sgbelief {__version__}",
        "vocabulary": sorted(graph.vocabulary) if graph.vocabulary is not None else None,
        "clock": int(graph.clock),
        "meta": _jsonable(graph.meta, "meta"),
        "graph_attrs": _jsonable(dict(g.graph), "graph attributes"),
        "prior": [prov.prior_alpha, prov.prior_beta],
        "remember_compacted": prov.remember_compacted,
        "n_compacted": prov.n_compacted,
        "statuses": [s.value for s in statuses],
        "predicates": pred_names,
        "counts": {"nodes": len(node_ids), "edges": len(edges), "pairs": n_pairs, "entries": m,
                   "corroborated": len(clists), "corroborating_ids": len(cids), "timeline": len(arrays["timeline"]),
                   "quarantine": len(arrays["quarantine"]), "disagreement": len(arrays["disagreement"]),
                   "compacted_ids": len(compacted)},
        "node_ids": nid_spec,
        "node_attrs": node_attrs,
        "edge_keys": ekey_spec,
        "edge_attrs": edge_attrs,
    }
    text = json.dumps(header, separators=(",", ":"), allow_nan=False)
    arrays["header"] = np.frombuffer(text.encode("utf-8"), _U1)
    return arrays


def save_graph_npz(graph: SceneGraph, path: str | Path) -> Path:
    """Write ``graph`` as one uncompressed ``.npz`` atomically (temp file, fsync, rename)."""
    path = Path(path)
    with gc_paused():
        arrays = graph_to_arrays(graph)  # fails before touching disk

    def write(fh: BinaryIO) -> None:  # what np.savez writes, without its per-chunk copies
        with zipfile.ZipFile(fh, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for name, arr in arrays.items():
                arr = np.ascontiguousarray(arr)
                with zf.open(name + ".npy", mode="w", force_zip64=True) as member:
                    np.lib.format.write_array_header_1_0(member, np.lib.format.header_data_from_array_1_0(arr))
                    if arr.size:
                        member.write(memoryview(arr).cast("B"))

    atomic_write_binary(path, write)
    return path


# ======================================================================= loading
class _Archive:
    """Checked access to the arrays of an open ``NpzFile``: dtype, shape and member size are
    validated from the ``.npy`` header before the data is read (so a hostile header cannot make
    the reader allocate more than the file holds)."""

    def __init__(self, npz: Any, source: Path) -> None:
        self.npz = npz
        self.source = source
        self.size = os.path.getsize(source)
        self.names = set(npz.files)
        self.used: set[str] = set()

    def error(self, message: str) -> FormatError:
        return FormatError(message, path=self.source)

    def has(self, name: str) -> bool:
        return name in self.names

    def read(self, name: str, dtype: np.dtype, shape: tuple[int | None, ...]) -> np.ndarray:
        if name not in self.names:
            raise self.error(f"missing array '{name}'")
        self.used.add(name)
        try:
            info = self.npz.zip.getinfo(name + ".npy")
            if info.compress_type != zipfile.ZIP_STORED or info.compress_size != info.file_size \
                    or info.header_offset + info.file_size > self.size:
                raise self.error(f"array '{name}': zip member must be stored uncompressed inside the file")
            with self.npz.zip.open(info) as fp:
                version = np.lib.format.read_magic(fp)
                if version == (1, 0):
                    a_shape, fortran, a_dtype = np.lib.format.read_array_header_1_0(fp)
                elif version == (2, 0):
                    a_shape, fortran, a_dtype = np.lib.format.read_array_header_2_0(fp)
                else:
                    raise self.error(f"array '{name}': unsupported .npy version {version}")
                data_offset = fp.tell()
        except FormatError:
            raise
        except (zipfile.BadZipFile, zlib.error) as exc:  # small members are read whole: CRC checked here
            raise self.error(f"array '{name}': corrupt data ({exc})") from None
        except (KeyError, ValueError, OSError, EOFError) as exc:
            raise self.error(f"array '{name}': unreadable .npy header ({exc})") from None
        if a_dtype.hasobject:
            raise self.error(f"array '{name}': object (pickled) arrays are not allowed")
        if a_dtype != dtype:
            raise self.error(f"array '{name}': dtype {a_dtype.str}, expected {dtype.str}")
        if len(a_shape) != len(shape) or any(e is not None and a != e for a, e in zip(a_shape, shape)):
            want = "(" + ", ".join("*" if e is None else str(e) for e in shape) + ")"
            raise self.error(f"array '{name}': shape {tuple(a_shape)}, expected {want}")
        if fortran and len(a_shape) > 1:
            raise self.error(f"array '{name}': Fortran-ordered arrays are not allowed")
        nbytes = math.prod(a_shape) * dtype.itemsize
        if info.file_size != data_offset + nbytes:
            raise self.error(f"array '{name}': {info.file_size - data_offset} data bytes for {nbytes} expected "
                             "(truncated or padded)")
        try:
            arr = self.npz[name]
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error, MemoryError) as exc:
            raise self.error(f"array '{name}': corrupt data ({exc})") from None
        return arr

    def check_unused(self) -> None:
        extra = sorted(self.names - self.used)
        if extra:
            raise self.error(f"unexpected array '{extra[0]}' (not part of {FORMAT} version {VERSION})")



def _read_header(arch: _Archive) -> _Header:
    raw = arch.read("header", _U1, (None,))
    try:
        doc = json.loads(raw.tobytes().decode("utf-8"), parse_constant=_json_constant)
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


def _check_index(arch: _Archive, name: str, arr: np.ndarray, upper: int) -> None:
    if len(arr) and (int(arr.min()) < 0 or int(arr.max()) >= upper):
        bad = int(np.flatnonzero((arr < 0) | (arr >= upper))[0])
        raise arch.error(f"array '{name}': index {int(arr[bad])} at row {bad} out of range [0, {upper})")


def _segment_sums(x: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Per-segment sums in extended precision (np.longdouble: 64-bit mantissa on x86-64)."""
    out = np.zeros(len(lengths), dtype=np.longdouble)
    nonempty = lengths > 0
    if nonempty.any():
        out[nonempty] = np.add.reduceat(x.astype(np.longdouble), starts[nonempty])
    return out


def load_graph_npz(path: str | Path) -> SceneGraph:
    """Read a graph written by :func:`save_graph_npz`; any malformed, truncated, edited or hostile
    file raises FormatError naming the array or header field (and no graph is returned)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no saved scene graph at {path}")
    try:
        npz = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise FormatError(f"not an .npz archive (truncated or another format): {exc}", path=path) from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise FormatError("a single .npy array, not an .npz scene graph archive", path=path)
    with npz, young_collections_only():
        return _load(_Archive(npz, path))


def _load(arch: _Archive) -> SceneGraph:
    h = _read_header(arch)
    c = h.counts
    n, n_pairs, m = c.nodes, c.pairs, c.entries
    statuses = [EntryStatus(s) for s in h.statuses]
    # ------------------------------------------------ read and validate every array first
    if h.node_ids.kind not in ("str", "int", "json"):
        raise arch.error("header field 'node_ids.kind': node ids must be stored as str, int or json")
    node_ids = _decode_values(arch, "node_id", h.node_ids.model_dump(), n)
    for i, v in enumerate(node_ids if h.node_ids.kind == "json" else ()):
        if isinstance(v, bool) or not isinstance(v, (str, int)):
            raise arch.error(f"array 'node_id' row {i}: node ids must be strings or integers, got {v!r}")
    src = arch.read("edge_source", _I8, (c.edges,))
    dst = arch.read("edge_target", _I8, (c.edges,))
    _check_index(arch, "edge_source", src, n)
    _check_index(arch, "edge_target", dst, n)
    edge_keys = _decode_values(arch, "edge_key", h.edge_keys.model_dump(), c.edges)
    for i, k in enumerate(edge_keys if h.edge_keys.kind in ("json", "float") else ()):
        if not isinstance(k, (str, int, float, bool, type(None))):
            raise arch.error(f"array 'edge_key' row {i}: edge keys must be scalars, got {k!r}")
    pair_node = arch.read("pair_node", _I8, (n_pairs,))
    _check_index(arch, "pair_node", pair_node, n)
    pair_pred = arch.read("pair_predicate", _I4, (n_pairs,))
    _check_index(arch, "pair_predicate", pair_pred, len(h.predicates))
    alpha = arch.read("pair_alpha", _F8, (n_pairs,))
    beta = arch.read("pair_beta", _F8, (n_pairs,))
    for name, arr in (("pair_alpha", alpha), ("pair_beta", beta)):
        bad = ~(np.isfinite(arr) & (arr > 0))
        if bad.any():
            raise arch.error(f"array '{name}': row {int(np.flatnonzero(bad)[0])} is not a finite number > 0")
    lengths = arch.read("pair_length", _I8, (n_pairs,))
    if n_pairs and (int(lengths.min()) < 0 or int(lengths.max()) > m):
        raise arch.error(f"array 'pair_length': lengths must be in [0, {m}]")
    if int(lengths.sum()) != m:
        raise arch.error(f"array 'pair_length': lengths add up to {int(lengths.sum())}, header counts {m} entries")
    t = arch.read("entry_t", _I8, (m,))
    da = arch.read("entry_d_alpha", _F8, (m,))
    db = arch.read("entry_d_beta", _F8, (m,))
    for name, arr in (("entry_d_alpha", da), ("entry_d_beta", db)):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise arch.error(f"array '{name}': non-finite increment at entry {int(np.flatnonzero(bad)[0])}")
    status = arch.read("entry_status", _U1, (m,))
    if m and int(status.max()) >= len(statuses):
        raise arch.error(f"array 'entry_status': status code {int(status.max())} out of range [0, {len(statuses)})")
    stance = arch.read("entry_stance", _I1, (m,))
    n_folded = arch.read("entry_n_folded", _I8, (m,))
    if m and int(n_folded.min()) < 1:
        raise arch.error("array 'entry_n_folded': every entry stands for at least 1 original entry")
    null = arch.read("entry_event_null", _B1, (m,))
    eids = _read_strings_later(arch, "entry_event", m)  # split when the entries are built
    corr_entry = arch.read("corroborated_entry", _I8, (c.corroborated,))
    _check_index(arch, "corroborated_entry", corr_entry, m)
    if len(corr_entry) > 1 and not (np.diff(corr_entry) > 0).all():
        raise arch.error("array 'corroborated_entry': entry indices must be strictly increasing")
    corr_len = arch.read("corroborated_length", _I8, (c.corroborated,))
    if c.corroborated and (int(corr_len.min()) < 0 or int(corr_len.max()) > c.corroborating_ids) \
            or int(corr_len.sum()) != c.corroborating_ids:
        raise arch.error("array 'corroborated_length': lengths must be >= 0 and add up to counts.corroborating_ids")
    corr_ids = _decode_values(arch, "corroborated_by", {"kind": "str"}, c.corroborating_ids)
    timeline = arch.read("timeline", _I8, (c.timeline,))
    _check_index(arch, "timeline", timeline, m)
    queues = {}
    for name, want in (("quarantine", EntryStatus.QUARANTINED), ("disagreement", EntryStatus.REFUSED)):
        idx = arch.read(name, _I8, (getattr(c, name),))
        _check_index(arch, name, idx, m)
        if len(idx) and not all(statuses[s] is want for s in np.unique(status[idx]).tolist()):
            raise arch.error(f"array '{name}': refers to an entry whose status is not {want.value!r}")
        queues[name] = idx
    compacted = _decode_values(arch, "compacted_ids", {"kind": "str"}, c.compacted_ids)
    # ---- Eq. 5 on every pair: prior + sum of counted increments must equal the stored belief
    offsets = np.zeros(n_pairs + 1, dtype=_I8)
    np.cumsum(lengths, out=offsets[1:])
    starts = offsets[:-1]
    counted = np.isin(status, [i for i, s in enumerate(statuses) if s in COUNTED])
    for name, stored, prior, d in (("alpha", alpha, h.prior[0], da), ("beta", beta, h.prior[1], db)):
        ref = np.longdouble(prior) + _segment_sums(np.where(counted, d, 0.0), starts, lengths)
        diff = np.abs(stored.astype(np.longdouble) - ref)
        tol = np.maximum(1e-9 * np.maximum(np.abs(stored), np.abs(ref)), 1e-9)
        bad = diff > tol
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            key = (node_ids[int(pair_node[i])], h.predicates[int(pair_pred[i])])
            raise arch.error(f"pair {i} {key!r}: stored {name}={float(stored[i])!r} does not equal prior + sum of "
                             f"logged increments ({float(ref[i])!r}); the file was edited or corrupted")
    # pair keys (node, predicate) before the node dicts: young collections untrack the tuples early
    node_arr = np.empty(n, dtype=object)
    node_arr[:] = node_ids
    pred_arr = np.empty(len(h.predicates), dtype=object)
    pred_arr[:] = h.predicates
    pair_nodes = node_arr[pair_node]
    pair_preds = pred_arr[pair_pred]
    pair_keys = list(zip(pair_nodes.tolist(), pair_preds.tolist()))
    node_attrs = _decode_records(arch, "node", h.node_attrs, n, True)
    edge_attrs = _decode_records(arch, "edge", h.edge_attrs, c.edges, False)
    arch.check_unused()
    arch.check_unused()
    # ------------------------------------------------------------- build the graph
    graph = SceneGraph(vocabulary=h.vocabulary)
    graph.clock = h.clock
    graph.meta = dict(h.meta)
    g = graph.nx
    g.graph.update(h.graph_attrs)
    _add_nodes(g, node_ids, node_attrs)
    if len(g) != n:
        raise arch.error("array 'node_id': duplicate node id")
    if c.edges:
        g.add_edges_from(zip(node_arr[src].tolist(), node_arr[dst].tolist(), edge_keys, edge_attrs))
    graph.provenance = _build_store(h, statuses, pair_keys, pair_nodes, pair_preds, alpha, beta, lengths, offsets,
                                    t, da, db, status, stance, n_folded, null, eids, corr_entry, corr_len,
                                    corr_ids, timeline, queues, compacted)
    if len(graph.provenance._pairs) != n_pairs:
        raise arch.error("arrays 'pair_node' / 'pair_predicate': duplicate (node, predicate) pair")
    return graph


def _add_nodes(g: nx.MultiDiGraph, ids: list[Any], attrs: list[dict[str, Any]]) -> None:
    """Insert nodes with their attribute dicts (taken as they are, not copied).

    An empty plain MultiDiGraph is filled through its documented adjacency dicts (``_node``,
    ``_succ``/``_adj``, ``_pred``) - add_nodes_from copies every dict and is ~4x slower."""
    plain = (type(g) is nx.MultiDiGraph and len(g) == 0 and g.node_attr_dict_factory is dict
             and g.adjlist_inner_dict_factory is dict and g._succ is g._adj)
    if not plain:  # pragma: no cover - SceneGraph always makes a plain MultiDiGraph
        g.add_nodes_from(zip(ids, attrs))
        return
    if any(n is None for n in ids):
        raise ValueError("None cannot be a node")
    g._node.update(zip(ids, attrs))
    g._succ.update(zip(ids, [{} for _ in range(len(ids))]))
    g._pred.update(zip(ids, [{} for _ in range(len(ids))]))
    clear = getattr(nx, "_clear_cache", None)
    if clear is not None:
        clear(g)


def _split(entries: list[Any], offsets: np.ndarray, lengths: np.ndarray) -> Iterable[list[Any]]:
    """The per-pair entry lists (consecutive runs of ``entries``), in pair order."""
    if len(lengths) and int(lengths.min()) == 1 and int(lengths.max()) == 1:
        return map(list, zip(entries))  # one entry per pair (zip reuses its 1-tuple)
    return map(entries.__getitem__, map(slice, offsets[:-1].tolist(), offsets[1:].tolist()))


def _build_store(h: _Header, statuses: list[EntryStatus], pair_keys: list[tuple[Any, str]],
                 pair_nodes: np.ndarray, pair_preds: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
                 lengths: np.ndarray,
                 offsets: np.ndarray, t: np.ndarray, da: np.ndarray, db: np.ndarray, status: np.ndarray,
                 stance: np.ndarray, n_folded: np.ndarray, null: np.ndarray, eids: Callable[[], list[str]],
                 corr_entry: np.ndarray, corr_len: np.ndarray, corr_ids: list[str], timeline: np.ndarray,
                 queues: dict[str, np.ndarray], compacted: list[str]) -> ProvenanceStore:
    """The ProvenanceStore from validated columns: beliefs, queues and pending entries now, the
    other entries, the event index and the timeline on first read (:class:`_LoadedEntries`)."""
    store = ProvenanceStore((h.prior[0], h.prior[1]), remember_compacted=h.remember_compacted)
    store._pairs = dict(zip(pair_keys, map(_PairLog, _pylist(alpha), _pylist(beta))))
    loaded = _LoadedEntries(statuses, pair_nodes, pair_preds, lengths, offsets, t, da, db, status, stance,
                            n_folded, null, eids, corr_entry, corr_len, corr_ids, timeline)
    # the pending entries exist at once: the queues hold them (transitions act on these objects)
    pending = np.flatnonzero(np.isin(status, [i for i, s in enumerate(statuses) if s in PENDING]))
    built = dict(zip(pending.tolist(), loaded.entries(pending))) if len(pending) else {}
    pick = built.__getitem__
    store.quarantine = deque(map(pick, queues["quarantine"].tolist()))
    store.disagreement = deque(map(pick, queues["disagreement"].tolist()))
    # per-pair pending lists in time order (stable), as the JSON loader builds them
    by_pair = store._pending_by_pair
    for e in map(pick, pending[np.argsort(t[pending], kind="stable")].tolist()):
        by_pair.setdefault((e.node, e.predicate), []).append(e)
    loaded.pending = built
    store._compacted_order.extend(compacted)  # bounded by remember_compacted: keeps the newest
    store.n_compacted = h.n_compacted
    if len(t):
        store.defer_entries(loaded)
    return store


class _LoadedEntries:
    """The validated entry columns of a load; :meth:`build` makes what the streaming store keeps
    (entry objects in each pair's log, the event index, the timeline), exactly as an eager load
    would, reusing the pending entries made at load time (:class:`~sgbelief.graph.provenance.DeferredEntries`)."""

    def __init__(self, statuses: list[EntryStatus], pair_nodes: np.ndarray, pair_preds: np.ndarray,
                 lengths: np.ndarray, offsets: np.ndarray, t: np.ndarray, da: np.ndarray, db: np.ndarray,
                 status: np.ndarray, stance: np.ndarray, n_folded: np.ndarray, null: np.ndarray,
                 eids: Callable[[], list[str]], corr_entry: np.ndarray, corr_len: np.ndarray, corr_ids: list[str],
                 timeline: np.ndarray) -> None:
        self.status_arr = np.empty(len(statuses), dtype=object)
        for i, s in enumerate(statuses):
            self.status_arr[i] = s
        self.pair_nodes, self.pair_preds, self.lengths, self.offsets = pair_nodes, pair_preds, lengths, offsets
        self.t, self.da, self.db, self.status, self.stance, self.n_folded = t, da, db, status, stance, n_folded
        self.null, self._eids, self._eid_arr = null, eids, None
        self.corr_entry, self.corr_len, self.corr_ids, self.timeline = corr_entry, corr_len, corr_ids, timeline
        #: entry index -> the entry already made (the pending ones)
        self.pending: dict[int, ProvenanceEntry] = {}

    def eid_array(self) -> np.ndarray:
        """Each entry's event id (None where the file says null), as an object array."""
        if self._eid_arr is None:
            arr = np.fromiter(self._eids(), object, len(self.t))
            if self.null.any():
                arr[self.null] = None
            self._eid_arr = arr
        return self._eid_arr

    def entries(self, rows: np.ndarray | None = None) -> list[ProvenanceEntry]:
        """New entry objects for the given entry indices (all when None), in that order."""
        pick = (lambda a: a) if rows is None else (lambda a: a[rows])  # noqa: E731
        pair_of = np.repeat(np.arange(len(self.lengths)), self.lengths)
        pairs = pick(pair_of)
        entries = list(map(ProvenanceEntry, pick(self.eid_array()).tolist(), _pylist(pick(self.t)),
                           _pylist(pick(self.da)), _pylist(pick(self.db)), self.status_arr[pick(self.status)].tolist(),
                           self.pair_nodes[pairs].tolist(), self.pair_preds[pairs].tolist(), pick(self.stance).tolist()))
        n_folded = pick(self.n_folded)
        folded = np.flatnonzero(n_folded != 1)
        at = entries.__getitem__
        set_folded = ProvenanceEntry.n_folded.__set__  # type: ignore[attr-defined]
        deque(map(set_folded, map(at, folded.tolist()), n_folded[folded].tolist()), maxlen=0)
        if len(self.corr_entry):
            bounds = np.zeros(len(self.corr_len) + 1, dtype=_I8)
            np.cumsum(self.corr_len, out=bounds[1:])
            where = np.arange(len(self.t)) if rows is None else np.full(len(self.t), -1, dtype=_I8)
            if rows is not None:
                where[rows] = np.arange(len(rows))
            for i, a, b in zip(where[self.corr_entry].tolist(), bounds[:-1].tolist(), bounds[1:].tolist()):
                if i >= 0:
                    entries[i].corroborated_by = self.corr_ids[a:b]
        return entries

    def build(self, store: ProvenanceStore) -> None:
        with young_collections_only():  # ~10⁶ long-lived objects, as in the load itself
            self._build(store)

    def _build(self, store: ProvenanceStore) -> None:
        entries = self.entries()
        for i, e in self.pending.items():  # the objects the queues hold
            entries[i] = e
        pick = entries.__getitem__
        # the loaded pairs come first in the store (pairs are only removed after materialising)
        logs = list(islice(store._pairs.values(), len(self.lengths)))
        set_entries = _PairLog.entries.__set__  # type: ignore[attr-defined]
        deque(map(set_entries, logs, _split(entries, self.offsets, self.lengths)), maxlen=0)
        # event index: each event's entries in log order
        named = np.flatnonzero(~self.null)
        ev = self.eid_array()[named].tolist()
        ents = list(map(pick, named.tolist()))
        # (an id with one entry maps to the entry itself, as ProvenanceStore.record builds it)
        by_event: dict[str, Any] = dict(zip(ev, ents))
        if len(by_event) != len(ev):  # some event has several entries
            by_event = {}
            for eid, e in zip(ev, ents):
                index_event(by_event, eid, e)
        store._by_event = by_event
        store._timeline.extend(map(pick, self.timeline.tolist()))
