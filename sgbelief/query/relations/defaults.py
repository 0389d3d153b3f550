"""The registry queries use unless told otherwise: :data:`DEFAULT_REGISTRY`, the built-in indoor and
outdoor relations, which users extend with :func:`relation` (a decorator) or :func:`register_relation`."""

from __future__ import annotations

from sgbelief.query.relations.indoor import INDOOR_RELATIONS
from sgbelief.query.relations.outdoor import OUTDOOR_RELATIONS
from sgbelief.query.relations.registry import RelationRegistry

__all__ = ["DEFAULT_REGISTRY", "relation", "register_relation"]

DEFAULT_REGISTRY = RelationRegistry()
DEFAULT_REGISTRY.include(INDOOR_RELATIONS)
DEFAULT_REGISTRY.include(OUTDOOR_RELATIONS)

#: ``@relation("is_large", needs=("bbox",))``: register a predicate in :data:`DEFAULT_REGISTRY`
relation = DEFAULT_REGISTRY.predicate
#: ``register_relation("is_large", fn, needs=("bbox",))``: the same, without the decorator
register_relation = DEFAULT_REGISTRY.register
