"""Compound queries over a scene graph: belief predicates x geometric relation predicates.

    from sgbelief.query import run_query, P
    res = run_query(graph, "is_chair & is_near_window")          # or a named query: "chair near window"
    res = run_query(graph, P("is_car") & P("is_stationary") & ~P("is_near_pedestrian"), tau=0.6)
    for m in res: print(m.explain())

    ans = refer(graph, "the trash can that is closest to the doors")   # one object (sgbelief.query.referring)
    ans.best, ans.ranked, print(ans.explain())

See docs/queries.md for the grammar, the probability model and the built-in predicates.
"""

from __future__ import annotations

from sgbelief.query.engine import Component, Match, QueryEngine, QueryResult, run_query
from sgbelief.query.language import Compound, Literal, P, QueryPredicateError, QuerySyntaxError, parse
from sgbelief.query.named import NamedQuery, find_named_query, load_query_set, named_queries
from sgbelief.query.referring import ReferAnswer, ReferringQuery, Relation, UtteranceError, parse_utterance, refer
from sgbelief.query.relations import (
    DEFAULT_REGISTRY,
    GeometryContext,
    RelationConfig,
    RelationRegistry,
    materialise_relations,
    register_relation,
    relation,
)

__all__ = [
    "Component", "Compound", "DEFAULT_REGISTRY", "GeometryContext", "Literal", "Match", "NamedQuery", "P",
    "QueryEngine", "QueryPredicateError", "QueryResult", "QuerySyntaxError", "RelationConfig",
    "RelationRegistry", "find_named_query", "load_query_set", "materialise_relations", "named_queries",
    "parse", "register_relation", "relation", "run_query",
    "ReferAnswer", "ReferringQuery", "Relation", "UtteranceError", "parse_utterance", "refer",
]
