"""``refer(graph, query)``: pick the scene, the class members and the anchors, then score.

The graph is a sgbelief ``SceneGraph`` (labels and/or beliefs) or a plain networkx graph whose
nodes carry ``bbox`` (or ``centroid``), ``label`` and ``scene``. Candidates and anchors always
come from one scene: ``scene=`` pins it; otherwise the scenes holding a member of every class of
the query are scored and the one that best explains the utterance is answered (with a warning
when several qualify).
"""

from __future__ import annotations

import warnings
from typing import Any

from sgbelief.query.referring.classes import NodeTable
from sgbelief.query.referring.model import ReferAnswer, ReferError, ReferringQuery
from sgbelief.query.referring.parse import parse_utterance
from sgbelief.query.referring.scoring import ReferConfig, score_scene

__all__ = ["refer"]

_MISSING = object()


def _empty(query: ReferringQuery, scene: Any, note: str) -> ReferAnswer:
    return ReferAnswer(query, scene, (), (), (), (note,))


def refer(graph: Any, query: ReferringQuery | str, *, scene: Any = _MISSING, index: NodeTable | None = None,
          config: ReferConfig | None = None, use_beliefs: bool = True) -> ReferAnswer:
    """Answer a referring query: the one object an utterance (or a :class:`ReferringQuery`) names.

    ``scene``: the scene to search (a node ``scene`` value; None is the scene of nodes without
    one); default: chosen as described in the module docstring. ``index``: a
    :class:`~sgbelief.query.referring.classes.NodeTable` built once with ``NodeTable.from_graph(graph)``
    to answer many queries on an unchanged graph. ``use_beliefs``: also count nodes by their
    ``is_<class>`` beliefs (default on; off reads labels only).

    Returns a :class:`ReferAnswer` (``.best``, ``.ranked``, ``.explain()``); ``best`` is None when
    no scene holds a candidate of the target class and the anchor class(es). Raises
    :class:`~sgbelief.query.referring.model.UtteranceError` for an utterance it cannot read and
    :class:`ReferError` for an unknown ``scene``.
    """
    q = parse_utterance(query) if isinstance(query, str) else query
    if not isinstance(q, ReferringQuery):
        raise ReferError(f"refer: expected an utterance or a ReferringQuery, got {type(query).__name__}")
    cfg = config or ReferConfig()
    table = index if index is not None else NodeTable.from_graph(graph)
    classes = [q.target, *q.anchors]
    if scene is not _MISSING:
        if not table.has_scene(scene):
            shown = ", ".join(map(repr, list(table.scene_nodes)[:20]))
            raise ReferError(f"refer: scene {scene!r} holds no node of this graph; scenes: {shown}")
        scenes = [scene]
    else:
        scenes = table.scenes_with(classes, use_beliefs=use_beliefs, commit_tau=cfg.commit_tau)
        if not scenes:
            missing = [c for c in classes if not table.scenes_with([c], use_beliefs=use_beliefs, commit_tau=cfg.commit_tau)]
            if missing:
                why = "no node of class " + ", ".join(repr(c) for c in missing)
            else:
                why = "no single scene holds every class of the query (" + ", ".join(repr(c) for c in classes) + ")"
            return _empty(q, None, why)
    best: tuple[ReferAnswer, float] | None = None
    for s in scenes:
        target = table.members(q.target, s, use_beliefs=use_beliefs, commit_tau=cfg.commit_tau)
        anchors = [table.members(a, s, use_beliefs=use_beliefs, commit_tau=cfg.commit_tau) for a in q.anchors]
        if not len(target) or not all(len(a) for a in anchors):
            missing = [c for c, m in zip(classes, [target, *anchors]) if not len(m)]
            ans = _empty(q, s, "no node of class " + ", ".join(repr(c) for c in missing) + f" in scene {s!r}")
            cand = (ans, -1.0)
        else:
            cand = score_scene(table, s, q, target, anchors, cfg)
        if best is None or cand[1] > best[1]:
            best = cand
    assert best is not None
    answer = best[0]
    if len(scenes) > 1:
        note = (f"{len(scenes)} scenes hold the query's classes; answered in {answer.scene!r}, the one that "
                "explains the utterance best (pass scene= to choose)")
        warnings.warn(f"refer: {note}", stacklevel=2)
        answer = ReferAnswer(answer.query, answer.scene, answer.ranked, answer.candidates, answer.anchors,
                             (*answer.notes, note))
    return answer
