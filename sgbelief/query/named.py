"""Named compound queries (``sgbelief/configs/queries/<dataset>.yaml``).

File format (``format: sgbelief.queries``, ``version: 1``)::

    dataset: scannet
    vocabulary: vocab/scannet.yaml        # relative to the configs directory
    relations: {near_distance: 1.0}       # RelationConfig overrides for this dataset
    queries:
      chair_near_window:
        title: chair near window
        group: original                   # or expansion
        belief: [is_chair]                # VLM-typed components
        geometric: [is_near_window]       # geometric-channel components ("!x" negates)
        expr: is_chair & is_near_window   # must equal belief & geometric, in that order
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from sgbelief.errors import FormatError, SgbeliefError
from sgbelief.query.language import Compound, Literal, QuerySyntaxError, parse
from sgbelief.query.relations import RelationConfig

__all__ = ["NamedQuery", "QuerySet", "load_query_set", "named_queries", "find_named_query", "suggest_named_queries",
           "UnknownNamedQueryError", "DATASETS"]

DATASETS: tuple[str, ...] = ("kitti360", "scannet")


class UnknownNamedQueryError(SgbeliefError, LookupError):
    """Plain words that are neither an expression nor a shipped named query ("car near unicorn")."""

    def __init__(self, text: str, suggestions: list[str]) -> None:
        self.text = text
        self.suggestions = suggestions
        hint = f"; did you mean {', '.join(repr(s) for s in suggestions)}?" if suggestions else \
            "; see sgbelief/configs/queries/*.yaml for the named queries, or write an expression such as 'is_car & is_stationary'"
        super().__init__(f"no such named query {text!r}{hint}")


@dataclass(frozen=True)
class NamedQuery:
    """A compound with its name, title, group and decomposition."""

    name: str
    title: str
    group: str
    dataset: str
    compound: Compound
    belief: tuple[Literal, ...]
    geometric: tuple[Literal, ...]
    config: RelationConfig

    @property
    def expression(self) -> str:
        return str(self.compound)


@dataclass(frozen=True)
class QuerySet:
    dataset: str
    vocabulary: str | None
    config: RelationConfig
    queries: dict[str, NamedQuery]
    path: Path


def _lit(text: Any, path: Path, where: str) -> Literal:
    try:
        c = parse(str(text))
    except QuerySyntaxError as exc:
        raise FormatError(f"{where}: {exc}", path=path) from None
    if len(c.literals) != 1:
        raise FormatError(f"{where}: expected one predicate, got {text!r}", path=path)
    return c.literals[0]


def load_query_set(path: str | Path) -> QuerySet:
    """Load and validate one named-query YAML file."""
    import yaml

    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise FormatError(f"invalid YAML: {exc}", path=path) from None
    except UnicodeDecodeError as exc:
        raise FormatError(f"not UTF-8 text (byte offset {exc.start})", path=path) from None
    if not isinstance(doc, Mapping) or doc.get("format") != "sgbelief.queries":
        raise FormatError("field 'format': expected 'sgbelief.queries'", path=path)
    if doc.get("version") != 1:
        raise FormatError(f"field 'version': unsupported {doc.get('version')!r} (expected 1)", path=path)
    dataset = str(doc.get("dataset") or path.stem)
    config = RelationConfig.from_mapping(doc.get("relations") or {})
    raw = doc.get("queries")
    if not isinstance(raw, Mapping) or not raw:
        raise FormatError("field 'queries': expected a non-empty mapping", path=path)
    queries: dict[str, NamedQuery] = {}
    for name, q in raw.items():
        where = f"queries.{name}"
        if not isinstance(q, Mapping):
            raise FormatError(f"{where}: expected a mapping", path=path)
        belief = tuple(_lit(x, path, f"{where}.belief") for x in q.get("belief") or [])
        geometric = tuple(_lit(x, path, f"{where}.geometric") for x in q.get("geometric") or [])
        if not belief:
            raise FormatError(f"{where}.belief: at least one VLM-typed predicate is required", path=path)
        if "expr" in q:
            try:
                compound = parse(str(q["expr"]))
            except QuerySyntaxError as exc:
                raise FormatError(f"{where}.expr: {exc}", path=path) from None
            if compound.literals != belief + geometric:
                raise FormatError(f"{where}.expr {q['expr']!r} does not match its decomposition "
                                  f"{' & '.join(map(str, belief + geometric))!r}", path=path)
        else:
            compound = Compound(belief + geometric)
        queries[str(name)] = NamedQuery(str(name), str(q.get("title") or name).strip(), str(q.get("group") or ""),
                                        dataset, compound, belief, geometric, config)
    vocab = doc.get("vocabulary")
    return QuerySet(dataset, None if vocab is None else str(vocab), config, queries, path)


@lru_cache(maxsize=None)
def _shipped(dataset: str) -> QuerySet:
    from sgbelief.resources import config_path

    return load_query_set(config_path("queries", f"{dataset}.yaml"))


def named_queries(dataset: str | None = None) -> dict[str, NamedQuery]:
    """Shipped named queries of one dataset (or of all, KITTI-360 first), by name."""
    out: dict[str, NamedQuery] = {}
    for ds in (DATASETS if dataset is None else (dataset,)):
        out.update(_shipped(ds).queries)
    return out


def find_named_query(text: str, dataset: str | None = None) -> NamedQuery | None:
    """The shipped query whose name or title is ``text`` (case- and space-insensitive), or None."""
    key = " ".join(text.strip().lower().replace("_", " ").split())
    try:
        qs = named_queries(dataset)
    except FileNotFoundError:
        return None
    for q in qs.values():
        if key in (q.name.replace("_", " "), " ".join(q.title.lower().replace(",", " ").split()),
                   " ".join(q.title.lower().split())):
            return q
    return None


def suggest_named_queries(text: str, dataset: str | None = None, n: int = 3) -> list[str]:
    """Titles of the shipped named queries closest to ``text`` (for "did you mean ...")."""
    import difflib

    key = " ".join(text.strip().lower().replace("_", " ").split())
    try:
        qs = named_queries(dataset)
    except FileNotFoundError:
        return []
    by_title = {q.title.lower(): q.title for q in qs.values()}
    by_title.update({q.name.replace("_", " "): q.title for q in qs.values()})
    out: list[str] = []
    for hit in difflib.get_close_matches(key, list(by_title), n=2 * n, cutoff=0.5):
        if by_title[hit] not in out:
            out.append(by_title[hit])
    return out[:n]
