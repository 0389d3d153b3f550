"""ConceptGraphs class names -> sgbelief predicates.

The ConceptGraphs backend's default is :meth:`ClassVocabulary.open_vocabulary` over the class list
ConceptGraphs runs with: every class its own, mutually exclusive predicate, names of one synonym
set (couch / sofa) one predicate. The closed, hand-written tables of
``sgbelief/configs/conceptgraphs/*.yaml`` are available by name (``"scannet"``).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import yaml

from sgbelief.errors import ConfigError
from sgbelief.fusion.compatibility import singular_name

_NON_WORD = re.compile(r"[^0-9a-z]+")


def normalise_class_name(name: str) -> str:
    """Lower-case, fold every run of non-alphanumerics into one ``_``: ``"Office chair" -> "office_chair"``."""
    return _NON_WORD.sub("_", str(name).strip().lower()).strip("_")


class ClassVocabulary:
    """Maps a detector class name to the predicate it asserts.

    Lookup order: explicit ``classes`` overrides, then aliases of the subsumption table,
    then ``is_<normalised name>``.  Names in ``ignore`` map to ``None`` (no evidence routed).
    """

    def __init__(
        self,
        classes: Mapping[str, str] | None = None,
        *,
        aliases: Mapping[str, str] | None = None,
        ignore: Iterable[str] = (),
        subsumption_path: Path | None = None,
        table: Any = None,
        name: str | None = None,
        class_names: Iterable[str] | None = None,
    ) -> None:
        self._map: dict[str, str] = {}
        for alias, pred in (aliases or {}).items():
            self._map[normalise_class_name(alias)] = pred
        for cname, pred in (classes or {}).items():
            self._map[normalise_class_name(cname)] = pred
        self._ignore = {normalise_class_name(n) for n in ignore}
        self.subsumption_path = subsumption_path
        self._table = table
        #: the vocabulary's name (its class list's, or the table file's stem)
        self.name = name or (getattr(table, "name", None) if table is not None else None) or \
            (subsumption_path.stem if subsumption_path is not None else "vocabulary")
        #: the detector class list an open vocabulary was derived from (None for a closed table)
        self.class_names: tuple[str, ...] | None = tuple(class_names) if class_names is not None else None

    # ---- construction -------------------------------------------------------------------
    @classmethod
    def from_yaml(cls, path: str | Path) -> ClassVocabulary:
        """Load a ``sgbelief/configs/conceptgraphs/*.yaml`` file (or a bare ``sgbelief/configs/vocab/*.yaml`` table)."""
        from sgbelief.resources import config_dir

        path = Path(path)
        if not path.exists():
            candidate = config_dir() / "conceptgraphs" / f"{path.name if path.suffix else path.name + '.yaml'}"
            if candidate.exists():
                path = candidate
            else:
                raise FileNotFoundError(f"ConceptGraphs vocabulary {str(path)!r} not found")
        try:
            data = yaml.safe_load(path.read_text()) or {}
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: invalid YAML: {exc}") from exc
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: top level must be a mapping")
        if data.get("format") == "sgbelief.vocabulary":  # a subsumption table used directly
            return cls(aliases=_aliases_of(data, path), subsumption_path=path, name=path.stem)
        if data.get("format") == "sgbelief.label_mapping":
            raise ConfigError(f"{path}: key 'format': a label mapping is not a class vocabulary; pass it as "
                              "mapping= (or the 'mapping' key of a sgbelief.cg_vocabulary file)")
        if data.get("format") not in (None, "sgbelief.cg_vocabulary"):
            raise ConfigError(f"{path}: key 'format': expected 'sgbelief.cg_vocabulary', got {data.get('format')!r}")
        classes = data.get("classes") or {}
        if not isinstance(classes, dict) or not all(isinstance(v, str) for v in classes.values()):
            raise ConfigError(f"{path}: key 'classes': expected a mapping class name -> predicate")
        ignore = data.get("ignore") or []
        if not isinstance(ignore, list):
            raise ConfigError(f"{path}: key 'ignore': expected a list of class names")
        if data.get("class_list") is not None:  # open vocabulary: derive the table
            unknown = sorted(set(data) - {"format", "version", "class_list", "taxonomy", "mapping", "classes", "ignore",
                                          "merge"})
            if unknown:
                raise ConfigError(f"{path}: key {unknown[0]!r}: not allowed with 'class_list'")
            if data.get("subsumption") is not None:
                raise ConfigError(f"{path}: key 'subsumption': give either 'subsumption' or 'class_list', not both")

            def local(key: str) -> Any:
                value = data.get(key)
                if value is None or not isinstance(value, str):
                    return value
                cand = path.parent / value
                return cand if cand.exists() else value

            merge = data.get("merge", False)
            if not (isinstance(merge, bool) or (isinstance(merge, list) and all(isinstance(m, str) for m in merge))):
                raise ConfigError(f"{path}: key 'merge': expected true, false or a list of group predicates")
            try:
                return cls.open_vocabulary(local("class_list"), taxonomy=local("taxonomy") or "indoor",
                                           mapping=local("mapping"), ignore=ignore, classes=classes, merge=merge)
            except (FileNotFoundError, ValueError) as exc:
                raise ConfigError(f"{path}: {exc}") from exc
        aliases: dict[str, str] = {}
        sub_path: Path | None = None
        sub = data.get("subsumption")
        if sub is not None:
            sub_path = Path(sub)
            if not sub_path.is_absolute():
                local = path.parent / sub_path
                sub_path = local if local.exists() else config_dir() / sub_path
            if not sub_path.exists():
                raise ConfigError(f"{path}: key 'subsumption': file {str(sub)!r} not found")
            sub_data = yaml.safe_load(sub_path.read_text()) or {}
            aliases = _aliases_of(sub_data, sub_path)
        return cls(classes, aliases=aliases, ignore=ignore, subsumption_path=sub_path, name=path.stem)

    @classmethod
    def open_vocabulary(cls, class_list: Any, *, taxonomy: Any = "indoor", mapping: Any = None,
                        ignore: Iterable[str] = ("wall", "floor", "ceiling"),
                        classes: Mapping[str, str] | None = None,
                        merge: bool | Iterable[str] = False) -> ClassVocabulary:
        """A vocabulary derived from a detector class list (a path, a shipped name such as
        ``scannet200`` / ``coco80`` / ``replica``, or a list of names), a taxonomy and an optional
        mapping into the geometric channel's labels (e.g. ``scannet200_nyu40``).

        Classes listed separately are separate, mutually exclusive predicates; the taxonomy merges
        only names of one synonym set (couch / sofa). ``merge`` also merges the taxonomy's groups of
        kinds: True for all, or the group predicates (``["is_table_or_desk"]``: table, desk, ...).
        See :mod:`sgbelief.fusion.open_vocab`."""
        from sgbelief.fusion.open_vocab import derive_table, resolve_class_list

        ignore = list(ignore)
        class_list = resolve_class_list(class_list)
        table = derive_table(class_list, taxonomy, mapping, ignore=ignore, merge=merge)
        aliases = {alias: pred for pred, spec in table.specs.items() for alias in spec.aliases}
        return cls(classes, aliases=aliases, ignore=ignore, table=table, name=class_list.name,
                   class_names=class_list.names)

    @classmethod
    def default(cls) -> ClassVocabulary:
        """The closed, hand-written ScanNet vocabulary (``sgbelief/configs/conceptgraphs/scannet.yaml``;
        also ``ConceptGraphsBackend(vocabulary="scannet")``). Not the backend's default, which is
        the open vocabulary of the class list ConceptGraphs runs with."""
        from sgbelief.resources import config_path

        return cls.from_yaml(config_path("conceptgraphs", "scannet.yaml"))

    # ---- lookup ------------------------------------------------------------------------
    def predicate(self, class_name: str) -> str | None:
        """Predicate asserted by a detection of ``class_name``; None for ignored classes."""
        key = normalise_class_name(class_name)
        if key in self._ignore:
            return None
        pred = self._map.get(key)
        if pred is None:  # plural detector prompts ("chairs", "shelves")
            pred = self._map.get(singular_name(key))
        return pred if pred is not None else f"is_{key}"

    def known_predicates(self) -> set[str]:
        """Predicates named explicitly by the vocabulary (aliases and overrides)."""
        return set(self._map.values())

    def table(self) -> Any:
        """The subsumption table (``SubsumptionTable``) for the geometric channel, or None."""
        if self._table is None and self.subsumption_path is not None:
            from sgbelief.fusion.compatibility import SubsumptionTable

            self._table = SubsumptionTable.from_yaml(self.subsumption_path)
        return self._table


def _aliases_of(data: Any, path: Path) -> dict[str, str]:
    preds = data.get("predicates") if isinstance(data, dict) else None
    if not isinstance(preds, dict):
        raise ConfigError(f"{path}: key 'predicates': expected a mapping")
    out: dict[str, str] = {}
    for pred, spec in preds.items():
        for alias in (spec or {}).get("aliases", []) or []:
            out[str(alias)] = str(pred)
    return out
