"""The compatibility predicate compat(phi_f, phi_g) in {T, ⊥, ∅} from a subsumption table (§4.2).

A table is written by hand (``sgbelief/configs/vocab/*.yaml``, :meth:`SubsumptionTable.from_yaml`) or derived
from a detector class list by :func:`sgbelief.fusion.open_vocab.derive_table`, which builds it from
this module's types (:meth:`SubsumptionTable.from_specs`); this module does not know that one.
"""

from __future__ import annotations

import importlib
import re
import warnings
from collections.abc import Iterable, Mapping
from enum import Enum
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from sgbelief.errors import ConfigError, FormatError, SgbeliefDeprecationWarning, UnknownPredicateError


class Verdict(str, Enum):
    """Three-valued verdict of the geometric channel on a foundation-model claim."""

    CORROBORATES = "corroborates"  #: T: the geometric label agrees with the claim
    CONTRADICTS = "contradicts"  #: ⊥: the geometric label explicitly disagrees
    NO_CLAIM = "no_claim"  #: ∅: out of vocabulary for the predicate, or the channel cannot assert

    @property
    def symbol(self) -> str:
        return {"corroborates": "T", "contradicts": "⊥", "no_claim": "∅"}[self.value]


def normalise_class_name(name: str) -> str:
    """'Office Chair' -> 'office_chair' (lower case, runs of non-alphanumerics to '_')."""
    return re.sub(r"[^0-9a-z]+", "_", name.strip().lower()).strip("_")


def singular_name(key: str) -> str:
    """A normalised name's singular, for matching spellings: ``chairs`` -> ``chair``, ``shelves`` ->
    ``shelf``, ``boxes`` -> ``box``, ``bodies`` -> ``body``; the last word only (``office_chairs``)."""
    head, _, last = key.rpartition("_")
    if len(last) > 3 and last.endswith("ies"):
        last = last[:-3] + "y"
    elif len(last) > 3 and last.endswith("ves"):
        last = last[:-3] + "f"
    elif len(last) > 3 and last.endswith(("sses", "xes", "zes", "ches", "shes")):
        last = last[:-2]
    elif len(last) > 2 and last.endswith("s") and not last.endswith(("ss", "us", "is")):
        last = last[:-1]
    return f"{head}_{last}" if head else last


#: where the deprecated ``SubsumptionTable.from_class_list`` lives now (module, name)
_FROM_CLASS_LIST_HOME = ("sgbelief.fusion.open_vocab", "derive_table")

VOCABULARY_FORMAT = "sgbelief.vocabulary"
VOCABULARY_VERSION = 1


class PredicateSpec(BaseModel):
    """One predicate of a vocabulary file: the channel labels that corroborate it (``positive``),
    contradict it (``negative``) and the detector class names that assert it (``aliases``).

    In an exhaustive vocabulary (:attr:`VocabularyFile.exhaustive`) ``negative`` is not written: it is
    every label outside ``positive`` and ``silent``. ``silent`` lists the labels that may bear a
    positive element without naming it (a window is set into a ``wall``): they decide nothing.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)
    positive: list[str] = Field(default_factory=list)
    negative: list[str] = Field(default_factory=list)
    silent: list[str] = Field(default_factory=list)
    aliases: list[str] = Field(default_factory=list)

    @model_validator(mode="after")
    def _disjoint(self) -> PredicateSpec:
        if not self.positive and not self.negative:
            raise ValueError("a predicate needs a positive or a negative label set")
        for other, name in ((self.negative, "negative"), (self.silent, "silent")):
            both = set(self.positive) & set(other)
            if both:
                raise ValueError(f"labels {sorted(both)} are in both the positive and the {name} set")
        return self


class VocabularyFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    format: Literal["sgbelief.vocabulary"] = VOCABULARY_FORMAT
    version: int = Field(VOCABULARY_VERSION, strict=True)
    name: str = "vocabulary"
    labels: list[str] | None = None
    #: the channel gives each element exactly one label of ``labels`` (NYU40, Cityscapes): a label
    #: outside a predicate's positive and silent sets denies it, so negative sets are derived
    exhaustive: bool = False
    predicates: dict[str, PredicateSpec]

    @field_validator("version")
    @classmethod
    def _version(cls, v: int) -> int:
        if v != VOCABULARY_VERSION:
            raise ValueError(f"unsupported version {v} (this sgbelief reads version {VOCABULARY_VERSION})")
        return v

    @field_validator("predicates")
    @classmethod
    def _non_empty(cls, v: dict[str, PredicateSpec]) -> dict[str, PredicateSpec]:
        if not v:
            raise ValueError("at least one predicate is required")
        for name in v:
            if not name or not name.strip():
                raise ValueError("predicate names must be non-empty")
        return v

    @model_validator(mode="after")
    def _labels_known(self) -> VocabularyFile:
        if self.labels is not None:
            known = set(self.labels)
            for pred, spec in self.predicates.items():
                unknown = (set(spec.positive) | set(spec.negative) | set(spec.silent)) - known
                if unknown:
                    raise ValueError(f"predicate {pred!r} uses labels {sorted(unknown)} missing from 'labels'")
        return self

    @model_validator(mode="after")
    def _derive_negatives(self) -> VocabularyFile:
        """exhaustive: negative(phi) = labels - positive(phi) - silent(phi), in label order."""
        if not self.exhaustive:
            for pred, spec in self.predicates.items():
                if spec.silent:
                    raise ValueError(f"predicate {pred!r}: 'silent' needs 'exhaustive: true' (otherwise every "
                                     "label outside 'positive' and 'negative' is already silent)")
            return self
        if not self.labels:
            raise ValueError("'exhaustive: true' needs the channel's 'labels' (negative sets are derived from them)")
        for pred, spec in self.predicates.items():
            if spec.negative:
                raise ValueError(f"predicate {pred!r}: 'negative' is derived in an exhaustive vocabulary "
                                 "(every label outside 'positive' and 'silent'); list exceptions under 'silent'")
            keep = set(spec.positive) | set(spec.silent)
            derived = [lab for lab in self.labels if lab not in keep]
            self.predicates[pred] = spec.model_copy(update={"negative": derived})
        return self


class SubsumptionTable:
    """Per-predicate positive and negative label sets.

    ``outcome(phi, label)`` is 1 when the label is in phi's positive set, 0 when it is in the
    negative set, None otherwise: the calibration outcome y (§4.1). ``verdict(phi, label, c)``
    is T / ⊥ / ∅ from the same sets, with T and ⊥ swapped when c < 0.5 (the claim leans to
    "not phi"; Alg. 1 line 5).
    """

    def __init__(
        self,
        predicates: Mapping[str, PredicateSpec | Mapping[str, Any]],
        *,
        name: str = "vocabulary",
        labels: Iterable[str] | None = None,
    ) -> None:
        try:
            parsed = VocabularyFile(predicates=dict(predicates), name=name, labels=list(labels) if labels else None)
        except ValidationError as exc:
            raise ConfigError(_pydantic_message(exc, "vocabulary")) from exc
        self._init(parsed)

    def _init(self, parsed: VocabularyFile, ambiguous_labels: Iterable[str] = ()) -> None:
        self.name = parsed.name
        self.specs: dict[str, PredicateSpec] = dict(parsed.predicates)
        self.labels: frozenset[str] | None = frozenset(parsed.labels) if parsed.labels else None
        #: labels that decide nothing for any predicate (open-vocabulary tables: otherprop, object, ...)
        self.ambiguous_labels: frozenset[str] = frozenset(ambiguous_labels)
        self._outcomes: dict[str, dict[str, int]] = {}
        self._alias: dict[str, str] = {}
        for pred, spec in self.specs.items():
            table = {lab: 0 for lab in spec.negative}
            table.update({lab: 1 for lab in spec.positive})
            for lab, y in list(table.items()):  # a channel may spell 'office chair' as 'office_chair'
                table.setdefault(normalise_class_name(lab), y)
            self._outcomes[pred] = table
            for alias in [*spec.aliases, *spec.positive]:
                self._alias.setdefault(normalise_class_name(alias), pred)
            self._alias.setdefault(normalise_class_name(pred.removeprefix("is_")), pred)
        self._exclusive: dict[str, tuple[str, ...]] | None = None  # computed on first use
        #: label -> the predicates whose positive set holds it (what the label itself asserts)
        self._asserted: dict[str, tuple[str, ...]] = {}
        for pred, table in self._outcomes.items():
            for lab, y in table.items():
                if y == 1:
                    self._asserted[lab] = (*self._asserted.get(lab, ()), pred)

    @classmethod
    def from_yaml(cls, path: str | Path) -> SubsumptionTable:
        """Load ``predicates: {phi: {positive: [...], negative: [...], aliases: [...]}}``."""
        p = Path(path)
        try:
            raw = yaml.safe_load(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            line = mark.line + 1 if mark is not None else None
            raise FormatError(f"malformed YAML: {getattr(exc, 'problem', exc)}", path=p, line=line) from exc
        except UnicodeDecodeError as exc:
            raise FormatError(f"not UTF-8 text (byte offset {exc.start})", path=p) from None
        if not isinstance(raw, dict):
            raise FormatError("a vocabulary file must be a YAML mapping with a 'predicates' key", path=p)
        try:
            parsed = VocabularyFile.model_validate(raw)
        except ValidationError as exc:
            raise ConfigError(f"{p}: {_pydantic_message(exc, '')}") from exc
        table = cls.__new__(cls)
        table._init(parsed)
        return table

    @classmethod
    def from_specs(cls, specs: Mapping[str, PredicateSpec], *, name: str, labels: Iterable[str],
                   ambiguous_labels: Iterable[str] = ()) -> SubsumptionTable:
        """A table from specs that are valid by construction (a derivation such as
        :func:`sgbelief.fusion.open_vocab.derive_table`): no re-validation. ``ambiguous_labels``:
        channel labels that decide nothing for any predicate."""
        table = cls.__new__(cls)
        table._init(VocabularyFile.model_construct(format="sgbelief.vocabulary", version=1, name=name,
                                                   labels=list(labels), predicates=dict(specs)),
                    ambiguous_labels)
        return table

    @classmethod
    def from_class_list(cls, classes: Any, taxonomy: Any = "indoor", mapping: Any = None, *,
                        ignore: Iterable[str] = (), name: str | None = None) -> SubsumptionTable:
        """Deprecated: :func:`sgbelief.fusion.open_vocab.derive_table` (same arguments), which
        derives a table from a detector class list, a taxonomy and an optional label mapping."""
        home, name_there = _FROM_CLASS_LIST_HOME
        warnings.warn(f"SubsumptionTable.from_class_list is deprecated; use {home}.{name_there}",
                      SgbeliefDeprecationWarning, stacklevel=2)
        derive = getattr(importlib.import_module(home), name_there)  # a deprecated alias: no import arrow
        return derive(classes, taxonomy, mapping, ignore=ignore, name=name)  # type: ignore[no-any-return]

    @classmethod
    def shipped(cls, name: str) -> SubsumptionTable:
        """One of the vocabularies in ``sgbelief/configs/vocab`` (``scannet``, ``kitti360``); an
        unknown name is a :class:`ConfigError` listing the shipped ones."""
        from sgbelief.resources import config_dir, config_path

        known = sorted(p.stem for p in (config_dir() / "vocab").glob("*.yaml"))
        if name not in known:
            raise ConfigError(f"unknown vocabulary {name!r}: give a vocabulary YAML file or a shipped name "
                              f"({', '.join(known) or 'none found under ' + str(config_dir() / 'vocab')})")
        return cls.from_yaml(config_path("vocab", f"{name}.yaml"))

    @classmethod
    def resolve(cls, spec: SubsumptionTable | str | Path) -> SubsumptionTable:
        """A table instance as is, a YAML path, or a shipped name (``scannet``, ``kitti360``).
        A name is a file only when it ends in .yaml/.yml or names an existing file, so a folder
        that happens to be called ``scannet`` in the working directory does not hide the shipped table."""
        if isinstance(spec, SubsumptionTable):
            return spec
        path = Path(spec)
        if path.suffix in (".yaml", ".yml") or path.is_file():
            return cls.from_yaml(path)
        return cls.shipped(str(spec))

    # ------------------------------------------------------------------ queries
    @property
    def predicates(self) -> list[str]:
        return list(self.specs)

    def __contains__(self, predicate: object) -> bool:
        return predicate in self.specs

    def require(self, predicate: str) -> None:
        if predicate not in self.specs:
            raise UnknownPredicateError(predicate, self.specs)

    def outcome(self, predicate: str, label: str | None) -> int | None:
        """Calibration outcome y for (phi, geometric label): 1, 0 or None (not decisive)."""
        if label is None:
            return None
        table = self._outcomes.get(predicate)
        return None if table is None else table.get(label)

    def verdict(self, predicate: str, label: str | None, confidence: float) -> Verdict:
        """compat(phi_f, phi_g) with the sign flip for c < 0.5."""
        y = self.outcome(predicate, label)
        if y is None:
            return Verdict.NO_CLAIM
        agrees = (y == 1) == (confidence >= 0.5)
        return Verdict.CORROBORATES if agrees else Verdict.CONTRADICTS

    def asserted_by(self, label: str) -> tuple[str, ...]:
        """The predicates a geometric label asserts: those whose positive set holds it, in table
        order (``chair`` -> ``("is_chair",)``; an ambiguous or unknown label -> ``()``)."""
        return self._asserted.get(label, ())

    def asserted_tables(self) -> dict[str, tuple[str, ...]]:
        """label -> :meth:`asserted_by` (read-only use in hot loops)."""
        return self._asserted

    def exclusive_with(self, predicate: str) -> tuple[str, ...]:
        """The predicates that cannot hold together with ``predicate`` on one element.

        phi and psi exclude each other when every label asserting one of them denies the other:
        pos(phi) ⊆ neg(psi) or pos(psi) ⊆ neg(phi) (both positive sets non-empty). Whatever bears
        a label of pos(phi) is then, by the table, not a psi. Concrete classes of an open vocabulary
        exclude each other; ``is_car`` and ``is_stationary`` do not. In table order.
        """
        ex = self._exclusive
        if ex is None:
            ex = self._exclusive = self._exclusion_sets()
        return ex.get(predicate, ())

    def exclusive_predicates(self) -> frozenset[str]:
        """The predicates that exclude at least one other (:meth:`exclusive_with`): the classes."""
        return frozenset(p for p in self.specs if self.exclusive_with(p))

    def _exclusion_sets(self) -> dict[str, tuple[str, ...]]:
        pos = {p: frozenset(spec.positive) for p, spec in self.specs.items()}
        neg = {p: frozenset(spec.negative) for p, spec in self.specs.items()}
        out: dict[str, set[str]] = {p: set() for p in self.specs}
        preds = list(self.specs)
        for i, p in enumerate(preds):
            for q in preds[i + 1:]:
                if pos[p] and pos[q] and (pos[p] <= neg[q] or pos[q] <= neg[p]):
                    out[p].add(q)
                    out[q].add(p)
        return {p: tuple(q for q in preds if q in out[p]) for p in preds}

    def predicate_for_class(self, class_name: str) -> str | None:
        """The predicate a detector class name asserts (via aliases / positive labels), or None."""
        return self._alias.get(normalise_class_name(class_name))

    def outcome_tables(self) -> dict[str, dict[str, int]]:
        """label -> y per predicate (read-only use in hot loops)."""
        return self._outcomes

    def __repr__(self) -> str:
        return f"SubsumptionTable(name={self.name!r}, predicates={self.predicates})"


def _pydantic_message(exc: ValidationError, prefix: str) -> str:
    parts = []
    for err in exc.errors()[:3]:
        loc = ".".join(str(x) for x in err["loc"])
        key = f"{prefix}.{loc}" if prefix and loc else (loc or prefix)
        parts.append(f"key '{key}': {err['msg'].removeprefix('Value error, ')}")
    return "; ".join(parts)
