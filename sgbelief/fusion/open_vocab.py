"""Open-vocabulary subsumption tables: derived from a class list, a small taxonomy and a label mapping.

ConceptGraphs runs with open class lists (ScanNet200, Replica, COCO-80, a user's own). Instead of
hand-written negative sets, the table is derived:

* every class name of the detector's list is a *concrete* class, and concrete classes are mutually
  exclusive (a geometric ``sofa`` contradicts ``is_tv``): two names listed separately are two
  predicates;
* a taxonomy ``synonyms`` entry makes one predicate cover the names that mean the same thing
  (``is_sofa``: sofa, couch); a ``groups`` entry (kinds: ``is_table_or_desk``: table, desk, coffee
  table) does the same only when asked (``merge=True``, or ``merge=[predicate, ...]``), since the
  class list had them as separate classes; every other class ``c`` gets the predicate ``is_<c>``;
* ``hypernyms`` are general labels that stand for several classes (``seating``: chair, sofa,
  bench); ``ambiguous`` labels (``otherprop``, ``object``) stand for nothing decidable.

Each geometric label ``L`` denotes a set ``E(L)`` of the detector's concrete classes: ``{L}`` for a
concrete class, the listed classes for a hypernym, the classes mapped onto ``L`` when a mapping file
translates the detector's vocabulary into the channel's (ScanNet200 -> NYU40). For a predicate with
extension ``E(P)``:

* ``E(L)`` inside ``E(P)``: **T** (outcome 1);
* ``E(L)`` disjoint from ``E(P)``: **⊥** (outcome 0), including a concrete channel label no class
  of the list maps to (a ``wall`` is no chair);
* overlapping, or ``L`` ambiguous: **∅** (no outcome).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, ValidationError, field_validator, model_validator

from sgbelief.errors import FormatError
from sgbelief.fusion.compatibility import PredicateSpec, SubsumptionTable, normalise_class_name, singular_name

__all__ = ["Taxonomy", "LabelMapping", "ClassList", "load_class_list", "derive_table", "verdict_matrix"]


# ---------------------------------------------------------------------------------------- files
class TaxonomyFile(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    format: str = "sgbelief.taxonomy"
    version: int = 1
    name: str = "taxonomy"
    synonyms: dict[str, list[str]] = {}
    groups: dict[str, list[str]] = {}
    hypernyms: dict[str, list[str]] = {}
    ambiguous: list[str] = []

    @field_validator("format")
    @classmethod
    def _format(cls, v: str) -> str:
        if v != "sgbelief.taxonomy":
            raise ValueError(f"expected 'sgbelief.taxonomy', got {v!r}")
        return v

    @field_validator("groups", "synonyms")
    @classmethod
    def _groups(cls, v: dict[str, list[str]], info: Any) -> dict[str, list[str]]:
        kind = "group" if info.field_name == "groups" else "synonym set"
        seen: dict[str, str] = {}
        for pred, names in v.items():
            if not pred.startswith("is_"):
                raise ValueError(f"{kind} {pred!r}: predicate names start with 'is_'")
            if not names:
                raise ValueError(f"{kind} {pred!r}: at least one class name is required")
            for n in names:
                key = normalise_class_name(n)
                if key in seen and seen[key] != pred:
                    raise ValueError(f"class {n!r} is in both {kind} {seen[key]!r} and {kind} {pred!r}")
                seen[key] = pred
        return v

    @model_validator(mode="after")
    def _synonyms_inside_groups(self) -> TaxonomyFile:
        group_of = {normalise_class_name(n): g for g, names in self.groups.items() for n in names}
        for pred, names in self.synonyms.items():
            met = {group_of.get(normalise_class_name(n)) for n in names}
            if met != {None} and len(met) != 1:
                raise ValueError(f"synonym set {pred!r} meets a group but does not lie inside one "
                                 f"(groups: {sorted(g for g in met if g)})")
        return self


class LabelMappingFile(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)
    format: str = "sgbelief.label_mapping"
    version: int = 1
    source: str
    target: str
    #: source (detector) class -> target (channel) label; null: the class has no target label
    map: dict[str, str | None]
    #: target labels no source class maps to (they still contradict every predicate), optional
    target_labels: list[str] = []
    #: target labels that decide nothing (otherprop, otherfurniture, ...)
    ambiguous: list[str] = []

    @field_validator("format")
    @classmethod
    def _format(cls, v: str) -> str:
        if v != "sgbelief.label_mapping":
            raise ValueError(f"expected 'sgbelief.label_mapping', got {v!r}")
        return v


def _yaml_lines(text: str) -> dict[tuple[str, ...], int]:
    """1-based line of every mapping key / sequence item, by path (for error messages)."""
    import yaml

    out: dict[tuple[str, ...], int] = {}

    def walk(node: Any, path: tuple[str, ...]) -> None:
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                p = (*path, str(k.value))
                out[p] = k.start_mark.line + 1
                walk(v, p)
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                p = (*path, str(i))
                out[p] = v.start_mark.line + 1
                walk(v, p)

    try:
        root = yaml.compose(text)
    except yaml.YAMLError:
        return out
    if root is not None:
        walk(root, ())
    return out


def _load_yaml(path: Path) -> tuple[Any, dict[tuple[str, ...], int]]:
    import yaml

    text = path.read_text(encoding="utf-8")
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise FormatError(f"malformed YAML: {getattr(exc, 'problem', exc)}", path=path,
                          line=mark.line + 1 if mark is not None else None) from exc
    return data, _yaml_lines(text)


def _validate(model: type[BaseModel], data: Any, path: Path, lines: dict[tuple[str, ...], int]) -> Any:
    if not isinstance(data, dict):
        raise FormatError(f"expected a YAML mapping (a {model.__name__.removesuffix('File').lower()} file)", path=path)
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = tuple(str(x) for x in err["loc"])
        line = None
        for n in range(len(loc), 0, -1):
            line = lines.get(loc[:n])
            if line is not None:
                break
        key = ".".join(loc) or "(top level)"
        raise FormatError(f"key '{key}': {err['msg']}", path=path, line=line) from exc


@dataclass(frozen=True)
class Taxonomy:
    """Synonym sets (always one predicate), groups of kinds (one predicate when merged), hypernym
    labels and ambiguous labels."""

    groups: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    hypernyms: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    ambiguous: frozenset[str] = frozenset()
    name: str = "taxonomy"
    synonyms: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    @classmethod
    def from_yaml(cls, path: str | Path) -> Taxonomy:
        p = Path(path)
        data, lines = _load_yaml(p)
        parsed: TaxonomyFile = _validate(TaxonomyFile, data, p, lines)
        return cls.from_model(parsed)

    @classmethod
    def from_model(cls, parsed: TaxonomyFile) -> Taxonomy:
        return cls(groups={k: tuple(v) for k, v in parsed.groups.items()},
                   hypernyms={normalise_class_name(k): tuple(v) for k, v in parsed.hypernyms.items()},
                   ambiguous=frozenset(normalise_class_name(a) for a in parsed.ambiguous), name=parsed.name,
                   synonyms={k: tuple(v) for k, v in parsed.synonyms.items()})

    @classmethod
    def shipped(cls, name: str = "indoor") -> Taxonomy:
        from sgbelief.resources import config_path

        return cls.from_yaml(config_path("vocab", "taxonomy", f"{name}.yaml"))

    @classmethod
    def resolve(cls, spec: Taxonomy | str | Path | None) -> Taxonomy:
        if spec is None:
            return cls()
        if isinstance(spec, Taxonomy):
            return spec
        p = Path(spec)
        return cls.from_yaml(p) if p.suffix in (".yaml", ".yml") or p.exists() else cls.shipped(str(spec))

    def predicate_of(self, merge: bool | Iterable[str] = False) -> dict[str, str]:
        """normalised class name -> its predicate: the synonym set's, or, for the groups being
        merged (``merge``: True for every group, or the group predicates to merge), the group's."""
        out = {normalise_class_name(n): pred for pred, names in self.synonyms.items() for n in names}
        merged = _merged_groups(self, merge)
        for pred in merged:
            for n in self.groups[pred]:
                out[normalise_class_name(n)] = pred
        return out


def _merged_groups(tax: Taxonomy, merge: bool | Iterable[str]) -> list[str]:
    """The group predicates ``merge`` names (True: all of the taxonomy's); an unknown name is an error."""
    if merge is True:
        return list(tax.groups)
    if merge is False or merge is None:
        return []
    names = [merge] if isinstance(merge, str) else list(merge)
    unknown = [n for n in names if n not in tax.groups]
    if unknown:
        raise ValueError(f"merge: {unknown[0]!r} is no group of taxonomy {tax.name!r} "
                         f"(groups: {', '.join(tax.groups) or 'none'})")
    return names


@dataclass(frozen=True)
class LabelMapping:
    """Detector class -> geometric channel label (e.g. ScanNet200 -> NYU40)."""

    source: str
    target: str
    map: Mapping[str, str | None]
    target_labels: tuple[str, ...] = ()
    ambiguous: frozenset[str] = frozenset()
    path: Path | None = None

    @classmethod
    def from_yaml(cls, path: str | Path) -> LabelMapping:
        p = Path(path)
        data, lines = _load_yaml(p)
        parsed: LabelMappingFile = _validate(LabelMappingFile, data, p, lines)
        return cls(parsed.source, parsed.target, dict(parsed.map), tuple(parsed.target_labels),
                   frozenset(normalise_class_name(a) for a in parsed.ambiguous), p)

    @classmethod
    def shipped(cls, name: str) -> LabelMapping:
        from sgbelief.resources import config_path

        return cls.from_yaml(config_path("vocab", "mappings", f"{name}.yaml"))

    @classmethod
    def resolve(cls, spec: LabelMapping | str | Path | None) -> LabelMapping | None:
        if spec is None or isinstance(spec, LabelMapping):
            return spec
        p = Path(spec)
        return cls.from_yaml(p) if p.suffix in (".yaml", ".yml") or p.exists() else cls.shipped(str(spec))

    def labels(self) -> list[str]:
        out = list(dict.fromkeys([*(v for v in self.map.values() if v is not None), *self.target_labels]))
        return out


@dataclass(frozen=True)
class ClassList:
    """A detector's class names, in order (class id = position)."""

    names: tuple[str, ...]
    name: str = "classes"

    @classmethod
    def shipped(cls, name: str) -> ClassList:
        from sgbelief.resources import config_path

        return load_class_list(config_path("vocab", "classes", f"{name}.txt"))


def load_class_list(path: str | Path) -> ClassList:
    """A class list: a text file (one name a line, ``#`` comments), or YAML/JSON list or ``{classes: [...]}``.

    Empty and duplicate names (after normalisation) are errors naming the file and line.
    """
    import json

    p = Path(path)
    if p.suffix in (".yaml", ".yml", ".json"):
        if p.suffix == ".json":
            try:
                data = json.loads(p.read_text(encoding="utf-8"))
            except json.JSONDecodeError as exc:
                raise FormatError(f"malformed JSON: {exc.msg}", path=p, line=exc.lineno) from exc
            lines: dict[tuple[str, ...], int] = {}
        else:
            data, lines = _load_yaml(p)
        prefix: tuple[str, ...] = ()
        if isinstance(data, dict):
            if "classes" not in data:
                raise FormatError("key 'classes': missing (expected a list of class names)", path=p)
            data, prefix = data["classes"], ("classes",)
        if not isinstance(data, list):
            raise FormatError("expected a list of class names", path=p)
        entries = [(lines.get((*prefix, str(i))), x) for i, x in enumerate(data)]
    else:
        entries = []
        for i, raw in enumerate(p.read_text(encoding="utf-8").splitlines(), start=1):
            text = raw.split("#", 1)[0].strip()
            if text:
                entries.append((i, text))
    seen: dict[str, int | None] = {}
    names: list[str] = []
    for line, value in entries:
        if not isinstance(value, str) or not normalise_class_name(value):
            raise FormatError(f"class name {value!r}: expected a non-empty string", path=p, line=line)
        key = normalise_class_name(value)
        if key in seen:
            where = f" (first on line {seen[key]})" if seen[key] else ""
            raise FormatError(f"class name {value!r} is listed twice{where}", path=p, line=line)
        seen[key] = line
        names.append(value.strip())
    if not names:
        raise FormatError("the class list is empty", path=p)
    return ClassList(tuple(names), name=p.stem)


def resolve_class_list(spec: ClassList | Sequence[str] | str | Path) -> ClassList:
    if isinstance(spec, ClassList):
        return spec
    if isinstance(spec, (str, Path)):
        p = Path(spec)
        if p.exists() or p.suffix:
            return load_class_list(p)
        return ClassList.shipped(str(spec))
    return ClassList(tuple(str(s) for s in spec))


# ---------------------------------------------------------------------------------------- derivation
def derive_table(
    classes: ClassList | Sequence[str] | str | Path,
    taxonomy: Taxonomy | str | Path | None = "indoor",
    mapping: LabelMapping | str | Path | None = None,
    *,
    ignore: Iterable[str] = (),
    name: str | None = None,
    merge: bool | Iterable[str] = False,
) -> SubsumptionTable:
    """A :class:`SubsumptionTable` over the channel's labels for the detector's class list.

    Classes listed separately get separate, mutually exclusive predicates, except names of one
    synonym set of the taxonomy; ``merge`` (True, or group predicates such as
    ``["is_table_or_desk"]``) also merges the taxonomy's groups of kinds.

    ``classes`` is the detector's vocabulary; ``mapping`` (optional) translates it into the
    geometric channel's labels (without it the channel speaks the detector's vocabulary).
    ``ignore`` lists classes that get no predicate (wall, floor, ...); they remain channel labels.
    Aliases of each predicate are the class names it covers, so
    ``table.predicate_for_class(name)`` is the detector-side lookup.
    """
    cl = resolve_class_list(classes)
    tax = Taxonomy.resolve(taxonomy)
    mp = LabelMapping.resolve(mapping)
    group_of = tax.predicate_of(merge)
    ignored = {normalise_class_name(n) for n in ignore}
    display = {normalise_class_name(n): n for n in cl.names}
    concrete = [k for k in display if k not in tax.ambiguous and k not in tax.hypernyms]
    pred_of: dict[str, str] = {}
    for k in concrete:
        if k in ignored:
            continue
        one = singular_name(k)  # "chairs" next to "chair" is the same class
        base = one if one != k and one in display else k
        pred_of[k] = group_of.get(k) or group_of.get(base) or group_of.get(one) or f"is_{base}"
    extension: dict[str, set[str]] = {}
    for k, pred in pred_of.items():
        extension.setdefault(pred, set()).add(k)

    # channel label -> E(L) in the detector's concrete classes (None: ambiguous)
    labels: dict[str, frozenset[str] | None] = {}
    if mp is None:
        for k in concrete:
            labels[display[k]] = frozenset({k})
        for h, members in tax.hypernyms.items():
            labels[display.get(h, h)] = frozenset(normalise_class_name(m) for m in members)
        for a in tax.ambiguous:
            labels[display.get(a, a)] = None
        # a synonym of a listed class names that class (a channel's "television" for the list's "tv")
        for names in tax.synonyms.values():
            members = frozenset(normalise_class_name(n) for n in names) & set(concrete)
            if members:
                for n in names:
                    if normalise_class_name(n) not in display:
                        labels.setdefault(n, members)
    else:
        src = {normalise_class_name(k): v for k, v in mp.map.items()}
        inverse: dict[str, set[str]] = {}
        for k in concrete:
            target = src.get(k)
            if target is not None:
                inverse.setdefault(target, set()).add(k)
        for target in mp.labels():
            t_key = normalise_class_name(target)
            if t_key in mp.ambiguous or t_key in tax.ambiguous:
                labels[target] = None
            else:
                labels[target] = frozenset(inverse.get(target, ()))
        for a in mp.ambiguous:
            labels.setdefault(a, None)

    specs: dict[str, PredicateSpec] = {}
    for pred, ext in extension.items():
        pos, neg = [], []
        for lab, e in labels.items():
            if e is None:
                continue
            if e and e <= ext:
                pos.append(lab)
            elif not (e & ext):
                neg.append(lab)
        aliases = [display[k] for k in sorted(ext)]
        specs[pred] = PredicateSpec.model_construct(positive=pos, negative=neg, aliases=aliases)
    table_name = name or (f"{cl.name}->{mp.target}" if mp is not None else cl.name)
    return SubsumptionTable.from_specs(specs, name=table_name, labels=list(labels),
                                       ambiguous_labels=[lab for lab, e in labels.items() if e is None])


def verdict_matrix(table: SubsumptionTable, labels: Sequence[str] | None = None) -> tuple[list[str], list[str], list[list[str]]]:
    """(predicates, labels, rows of 'T' / '⊥' / '∅') for ``table`` at a confident (c >= 0.5) claim."""
    labs = list(labels) if labels is not None else sorted(table.labels or {
        lab for spec in table.specs.values() for lab in (*spec.positive, *spec.negative)})
    preds = table.predicates
    sym = {1: "T", 0: "⊥", None: "∅"}
    rows = [[sym[table.outcome(p, lab)] for lab in labs] for p in preds]
    return preds, labs, rows


def describe(table: SubsumptionTable) -> list[str]:
    """One line per predicate: its class names, the labels that corroborate, and what decides nothing."""
    all_labels = sorted(table.labels or set())
    out = []
    for pred, spec in table.specs.items():
        pos = set(spec.positive)
        neg = set(spec.negative)
        none = [lab for lab in all_labels if lab not in pos and lab not in neg]
        out.append(f"{pred}  [{', '.join(spec.aliases)}]  T: {sorted(pos) or '-'}  "
                   f"⊥: {len(neg)} labels  ∅: {none or '-'}")
    return out
