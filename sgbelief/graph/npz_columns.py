"""Columns of the binary layout: one Python value per row, stored as the tightest numpy array.

A value column's header spec :class:`ColumnSpec` ``{"kind", "shape"}`` says how::

    str   -> <name>.text / <name>.lengths    int  -> <name> <i8    bool -> <name> |b1
    float -> <name> <f8 of shape (rows, *shape)  json -> <name>.text / .lengths, one JSON text per row

A string column is one NUL-separated UTF-8 blob (``.text``), with the UTF-8 byte length of each
string (``.lengths``) only when a string itself holds a NUL. Decoding gives the Python values,
of the types a JSON round trip gives. The identity codes at the end map objects (nodes,
predicates, entries) to rows by address, without a second hash table over millions of them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable
from functools import partial
from itertools import chain
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from sgbelief.errors import FormatError
from sgbelief.graph.json_values import jsonable, restore_node_attr
from sgbelief.graph.npz_archive import B1, CHUNK, F8, I8, U1, NpzArchive

#: node attributes the JSON loader turns into tuples of float (see ``restore_node_attr``), by nesting depth
SPECIAL_DEPTH = {"centroid": 1, "bbox": 2}
_FLOAT_TYPES = frozenset({float, np.float64})
_SEP = "\x00"


class ColumnSpec(BaseModel):
    """How a value column is stored (its header entry)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    kind: str = Field(pattern="^(str|int|float|bool|json)$")
    shape: list[int] = []
    key: str | None = None


# ====================================================================== strings
def encode_strings(values: list[str] | tuple[str, ...], where: Callable[[int], str]) -> dict[str, np.ndarray]:
    """``.text``: UTF-8 of the strings joined by NUL. Only when a string itself holds a NUL is a
    ``.lengths`` array (UTF-8 byte length of each string) added. Raises TypeError on a non-str."""
    try:
        text = _SEP.join(values)
    except TypeError:
        i = next(i for i, v in enumerate(values) if not isinstance(v, str))
        raise TypeError(f"{where(i)}: expected a string, got {type(values[i]).__name__}") from None
    data = np.frombuffer(text.encode("utf-8", "surrogatepass"), U1)
    if not values or text.count(_SEP) == len(values) - 1:
        return {".text": data}
    return {".text": data, ".lengths": np.fromiter((len(v.encode("utf-8", "surrogatepass")) for v in values),
                                                    I8, len(values))}

def decode_strings(data: np.ndarray, lengths: np.ndarray | None, rows: int, err: Callable[[str], FormatError]
                    ) -> list[str]:
    """Inverse of :func:`encode_strings`; checks the text is UTF-8 and holds exactly ``rows`` strings."""
    return checked_strings(data, lengths, rows, err)()

def checked_strings(data: np.ndarray, lengths: np.ndarray | None, rows: int, err: Callable[[str], FormatError]
                     ) -> Callable[[], list[str]]:
    """:func:`decode_strings` with the split left to the caller: every check is made now, the
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

def read_strings(arch: NpzArchive, name: str, rows: int) -> list[str]:
    """A string column: ``<name>.text`` and, when present, ``<name>.lengths``."""
    return read_strings_later(arch, name, rows)()

def read_strings_later(arch: NpzArchive, name: str, rows: int) -> Callable[[], list[str]]:
    """:func:`read_strings`, checked now, split when the returned callable is called."""
    data = arch.read(name + ".text", U1, (None,))
    lengths = arch.read(name + ".lengths", I8, (rows,)) if arch.has(name + ".lengths") else None
    return checked_strings(data, lengths, rows, lambda msg: arch.error(f"array '{name}.text': {msg}"))

# ================================================================ value columns
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
        flat = np.fromiter(chain.from_iterable(level), F8, len(values) * math.prod(shape))
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
    first = _float_chunk(values[:CHUNK], depth, exact)
    if first is None or n <= CHUNK:
        return first
    shape, head = first
    width = math.prod(shape)
    flat = np.empty(n * width, dtype=F8)
    flat[:len(head)] = head
    for a in range(CHUNK, n, CHUNK):
        got = _float_chunk(values[a:a + CHUNK], depth, exact)
        if got is None or got[0] != shape:
            return None
        flat[a * width:a * width + len(got[1])] = got[1]
    return shape, flat

def encode_values(values: list[Any], where: Callable[[int], str], special: str | None = None
                   ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Pick the tightest kind for a column and encode it; anything irregular becomes per-row JSON."""
    try:
        return {"kind": "str"}, encode_strings(values, where)
    except TypeError:
        pass
    types = set(map(type, values))
    if types == {bool}:
        return {"kind": "bool"}, {"": np.array(values, dtype=B1)}
    if types == {int}:
        try:
            return {"kind": "int"}, {"": np.array(values, dtype=I8)}
        except OverflowError:
            pass
    block = None
    if types <= _FLOAT_TYPES:
        block = [], np.array(values, dtype=F8)
    elif special is not None and types <= {tuple, list}:
        block = _float_block(values, SPECIAL_DEPTH[special], exact=False)
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
    texts = [json.dumps(jsonable(v, where(i)), separators=(",", ":"), allow_nan=False) for i, v in enumerate(values)]
    return {"kind": "json"}, encode_strings(texts, where)

def value_array(spec: dict[str, Any], rows: int) -> tuple[np.dtype, tuple[int, ...]]:
    """(dtype, shape) of a numeric value column of ``rows`` rows."""
    kind = spec["kind"]
    if kind == "float":
        return F8, (rows, *spec.get("shape", []))
    return (I8 if kind == "int" else B1), (rows,)

def json_constant(name: str) -> Any:
    raise ValueError(f"non-finite number {name} is not allowed")

_SAMPLE = 1024  #: rows sampled to guess whether a numeric column has few distinct values
_FEW = 64  #: at most this many distinct values in the sample: try sharing Python objects


def pylist(arr: np.ndarray) -> list[Any]:
    """``arr.tolist()`` of a 1-d int64 / float64 array, except that when the column holds only a few
    distinct values (a constant, unit weights, flags) equal values share one Python object: far
    fewer allocations, same values. Values are compared bit for bit (``-0.0`` stays ``-0.0``)."""
    n = len(arr)
    if n < 4 * _SAMPLE or arr.dtype not in (F8, I8):
        return arr.tolist()
    bits = arr.view(I8)
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
        return pylist(arr)
    return list(zip(*(_float_tuples(arr[:, i]) for i in range(arr.shape[1]))))

def decode_values(arch: NpzArchive, name: str, spec: dict[str, Any], rows: int, special: str | None = None
                   ) -> list[Any]:
    """Read a value column back as Python values of the types a JSON round trip gives."""
    kind = spec["kind"]
    if kind in ("str", "json"):
        values = read_strings(arch, name, rows)
        if kind == "json":
            out = []
            for i, text in enumerate(values):
                try:
                    out.append(json.loads(text, parse_constant=json_constant))
                except (ValueError, RecursionError) as exc:
                    raise arch.error(f"array '{name}' row {i}: bad JSON value ({type(exc).__name__}: {exc})"
                                     ) from None
            values = out
    elif kind == "float":
        arr = arch.read(name, *value_array(spec, rows))
        finite = np.isfinite(arr.reshape(rows, -1)).all(axis=1) if arr.size else np.ones(rows, dtype=bool)
        if not finite.all():
            raise arch.error(f"array '{name}': non-finite value at row {int(np.flatnonzero(~finite)[0])}")
        shape = list(arr.shape[1:])
        if special is not None and len(shape) == SPECIAL_DEPTH[special] and 0 not in shape:
            return _float_tuples(arr)
        values = pylist(arr) if not shape else arr.tolist()
    else:
        arr = arch.read(name, *value_array(spec, rows))
        values = pylist(arr) if kind == "int" else arr.tolist()
    if special is not None:
        try:
            values = [restore_node_attr(special, v) for v in values]
        except (TypeError, ValueError) as exc:
            raise arch.error(f"array '{name}': {special} values must be nested sequences of numbers ({exc})") from None
    return values

# =============================================================== identity codes
def by_address(objs: Iterable[Any], n: int) -> tuple[np.ndarray, np.ndarray]:
    """(sorted addresses, row of each) of ``n`` objects."""
    ids = np.fromiter(map(id, objs), np.uint64, n)
    order = np.argsort(ids)
    return ids[order], order

def match_rows(sorted_ids: np.ndarray, order: np.ndarray, objs: Iterable[Any], n: int) -> np.ndarray:
    """Row of each object found (by address) among the sorted ones, -1 where none is."""
    vid = np.fromiter(map(id, objs), np.uint64, n)
    pos = np.minimum(np.searchsorted(sorted_ids, vid), len(sorted_ids) - 1)
    hit = sorted_ids[pos] == vid
    return np.where(hit, order[pos], -1).astype(I8)

def distinct_codes(values: list[Any] | tuple[Any, ...]) -> tuple[np.ndarray, list[Any]]:
    """(code of each value, distinct values in first-appearance order). Values are grouped by
    address first (predicates are usually a handful of shared string objects), then by equality."""
    ids = np.fromiter(map(id, values), np.uint64, len(values))
    _uid, first, inverse = np.unique(ids, return_index=True, return_inverse=True)
    objs = [values[i] for i in first.tolist()]
    distinct = list(dict.fromkeys(values[i] for i in np.sort(first).tolist()))
    code_of = {v: i for i, v in enumerate(distinct)}
    obj_code = np.fromiter(map(code_of.__getitem__, objs), I8, len(objs))
    return obj_code[inverse.reshape(-1)], distinct

def positions(objs: Iterable[Any], sorted_ids: np.ndarray, order: np.ndarray) -> np.ndarray:
    """Index in the flat entry list of each object (by identity); objects not in it are dropped."""
    ids = np.fromiter(map(id, objs), np.uint64)
    if not len(sorted_ids) or not len(ids):
        return np.zeros(0, dtype=I8)
    pos = np.minimum(np.searchsorted(sorted_ids, ids), len(sorted_ids) - 1)
    return order[pos[sorted_ids[pos] == ids]].astype(I8)
