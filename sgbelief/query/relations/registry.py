"""Named geometric predicates: :class:`GeoPredicate` (``fn(ctx, node) -> bool | None``) and the
:class:`RelationRegistry` that resolves a literal's name to one, exactly or through a *family*
(``is_near_<class>``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from sgbelief.errors import ConfigError, UnknownPredicateError
from sgbelief.query.relations.context import GeometryContext

__all__ = ["PredicateFn", "FamilyFactory", "GeoPredicate", "RelationRegistry"]

#: a geometric predicate: True / False, or None when the node lacks an attribute it needs
PredicateFn = Callable[[GeometryContext, Any], "bool | None"]


@dataclass(frozen=True)
class GeoPredicate:
    """A named geometric predicate: ``fn(ctx, node) -> bool | None``; ``needs`` lists the node
    attributes it reads (documentation and error messages only)."""

    name: str
    fn: PredicateFn
    needs: tuple[str, ...] = ()
    doc: str = ""

    def __call__(self, ctx: GeometryContext, node: Any) -> bool | None:
        value = self.fn(ctx, node)
        return None if value is None else bool(value)


FamilyFactory = Callable[[str], PredicateFn]


@dataclass(frozen=True)
class _Family:
    prefix: str
    factory: FamilyFactory
    needs: tuple[str, ...]
    doc: str


class RelationRegistry:
    """Named geometric predicates plus *families* (``is_near_<class>``): a family is a prefix and a
    factory called with the suffix. Exact names take precedence over families."""

    def __init__(self) -> None:
        self._preds: dict[str, GeoPredicate] = {}
        self._families: dict[str, _Family] = {}
        self._family_cache: dict[str, GeoPredicate] = {}

    def copy(self) -> RelationRegistry:
        new = RelationRegistry()
        new.include(self)
        return new

    def include(self, other: RelationRegistry, *, replace: bool = False) -> None:
        """Add every predicate and family of ``other``; a name registered in both needs ``replace=True``."""
        clash = sorted((set(self._preds) & set(other._preds)) | (set(self._families) & set(other._families)))
        if clash and not replace:
            raise ConfigError(f"relation(s) {clash} are already registered (pass replace=True)")
        self._preds.update(other._preds)
        self._families.update(other._families)
        self._family_cache.clear()

    def register(self, name: str, fn: PredicateFn, *, needs: Iterable[str] = (), doc: str | None = None,
                 replace: bool = False) -> GeoPredicate:
        """Register ``fn`` under ``name`` (an identifier); re-registering needs ``replace=True``."""
        if not name.isidentifier():
            raise ConfigError(f"relation name {name!r} is not an identifier")
        if name in self._preds and not replace:
            raise ConfigError(f"relation {name!r} is already registered (pass replace=True)")
        pred = GeoPredicate(name, fn, tuple(needs), (doc if doc is not None else (fn.__doc__ or "")).strip())
        self._preds[name] = pred
        self._family_cache.clear()
        return pred

    def predicate(self, name: str | None = None, *, needs: Iterable[str] = (), doc: str | None = None,
                  replace: bool = False) -> Callable[[PredicateFn], PredicateFn]:
        """Decorator form of :meth:`register` (name defaults to the function's name)."""

        def deco(fn: PredicateFn) -> PredicateFn:
            self.register(name or fn.__name__, fn, needs=needs, doc=doc, replace=replace)
            return fn

        return deco

    def register_family(self, prefix: str, factory: FamilyFactory, *, needs: Iterable[str] = (),
                        doc: str = "", replace: bool = False) -> None:
        """Register a family: any name ``<prefix><suffix>`` resolves to ``factory(suffix)``."""
        if prefix in self._families and not replace:
            raise ConfigError(f"relation family {prefix!r} is already registered (pass replace=True)")
        self._families[prefix] = _Family(prefix, factory, tuple(needs), doc.strip())
        self._family_cache.clear()

    def find(self, name: str) -> GeoPredicate | None:
        """The predicate called ``name`` (exact or via a family), or None."""
        pred = self._preds.get(name)
        if pred is not None:
            return pred
        pred = self._family_cache.get(name)
        if pred is not None:
            return pred
        for prefix in sorted(self._families, key=len, reverse=True):
            if name.startswith(prefix) and len(name) > len(prefix):
                fam = self._families[prefix]
                pred = GeoPredicate(name, fam.factory(name[len(prefix):]), fam.needs, fam.doc)
                self._family_cache[name] = pred
                return pred
        return None

    def get(self, name: str) -> GeoPredicate:
        """Like :meth:`find` but raises :class:`UnknownPredicateError` listing the known names."""
        pred = self.find(name)
        if pred is None:
            raise UnknownPredicateError(name, self.names())
        return pred

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self.find(name) is not None

    def names(self) -> list[str]:
        """Exact names plus family patterns (``is_near_<class>``)."""
        return sorted(self._preds) + sorted(f"{p}<class>" for p in self._families)

    def describe(self) -> list[tuple[str, tuple[str, ...], str]]:
        """(name, attributes needed, doc) for every predicate and family."""
        out = [(p.name, p.needs, p.doc) for p in self._preds.values()]
        out += [(f"{f.prefix}<class>", f.needs, f.doc) for f in self._families.values()]
        return sorted(out)
