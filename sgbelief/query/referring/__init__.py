"""Referring queries: the *one* object an utterance names ("the trash can closest to the doors").

    from sgbelief.query import refer, ReferringQuery
    ans = refer(graph, "select the trash can that is closest to the doors")
    ans = refer(graph, ReferringQuery(target="lamp", relation="between", anchors=["bed", "sofa"]))
    ans.best; ans.ranked; print(ans.explain())

Modules, one concept each: :mod:`~sgbelief.query.referring.model` (the query, relation and answer
values), :mod:`~sgbelief.query.referring.parse` (the utterance grammar),
:mod:`~sgbelief.query.referring.classes` (open-vocabulary class matching, the node table),
:mod:`~sgbelief.query.referring.geometry` (footprints and relation measures),
:mod:`~sgbelief.query.referring.allocentric` (sections and the anchor's front),
:mod:`~sgbelief.query.referring.scoring` (P(referent) over memberships, anchors and fronts) and
:mod:`~sgbelief.query.referring.resolve` (:func:`refer`). See docs/queries.md, "Referring queries".
"""

from __future__ import annotations

from sgbelief.query.referring.allocentric import SectionConfig
from sgbelief.query.referring.classes import NodeTable, class_key, singular_key
from sgbelief.query.referring.model import (
    AnchorChoice,
    CandidateScore,
    ReferAnswer,
    ReferError,
    ReferringQuery,
    Relation,
    UtteranceError,
)
from sgbelief.query.referring.parse import RELATION_PHRASES, normalise_utterance, parse_utterance
from sgbelief.query.referring.resolve import refer
from sgbelief.query.referring.scoring import ReferConfig

__all__ = [
    "AnchorChoice", "CandidateScore", "NodeTable", "RELATION_PHRASES", "ReferAnswer", "ReferConfig", "ReferError",
    "ReferringQuery", "Relation", "SectionConfig", "UtteranceError", "class_key", "normalise_utterance",
    "parse_utterance", "refer", "singular_key",
]
