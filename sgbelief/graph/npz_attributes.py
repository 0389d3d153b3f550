"""Attribute dicts (of nodes, of edges) in the binary layout, as key-set patterns.

``<prefix>_pattern`` gives each row's pattern, the header (:class:`RecordsSpec`) lists each
pattern's keys, and key j's values (the rows that have it, in row order) are the value column
``<prefix>_attr.<j>`` (:mod:`sgbelief.graph.npz_columns`). Dicts come back with the keys in their
pattern's order (dict equality does not depend on key order).
"""

from __future__ import annotations

from collections.abc import Callable
from itertools import chain
from operator import itemgetter
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict

from sgbelief.graph.npz_archive import CHUNK, I4, NpzArchive
from sgbelief.graph.npz_columns import SPECIAL_DEPTH, ColumnSpec, decode_values, encode_values


class RecordsSpec(BaseModel):
    """The key sets of a column of attribute dicts (its header entry)."""

    model_config = ConfigDict(strict=True)
    columns: list[ColumnSpec]
    patterns: list[list[int]]


def encode_records(dicts: list[dict[str, Any]], prefix: str, what: Callable[[int], str], special: bool
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
            for a in range(0, n, CHUNK):  # chunk by chunk: the dicts stay in cache across the keys
                chunk = dicts[a:a + CHUNK]
                lens.update(map(len, chunk))
                for col, get in zip(columns, getters):
                    col += map(get, chunk)
            uniform = lens == {len(keys)}
        except KeyError:
            pass
    if uniform:
        codes = np.zeros(n, dtype=I4)
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
        codes = np.fromiter(map(index.__getitem__, pats), I4, n)
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
        spec, arrs = encode_values(vals, lambda r, k=key, f=rows_of: f"{what(f(r))} attribute {k!r}",
                                    key if special and key in SPECIAL_DEPTH else None)
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

def decode_records(arch: NpzArchive, prefix: str, spec: RecordsSpec, n: int, special: bool) -> list[dict[str, Any]]:
    """The attribute dicts, in row order."""
    codes = arch.read(f"{prefix}_pattern", I4, (n,))
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
        sp = col.key if special and col.key in SPECIAL_DEPTH else None
        values.append(decode_values(arch, f"{prefix}_attr.{j}", col.model_dump(), rows, sp))
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
