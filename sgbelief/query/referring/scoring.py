"""P(v is the referent): the relation's geometry, taken in expectation over class memberships,
anchor identities and (for view-dependent relations) the anchor's front.

Notation, for one scene: ``p_v`` = P(node v is of the target class), ``q_a`` = P(node a is of the
anchor class) (1 or 0 for labelled nodes, the belief's posterior mean otherwise; see
:mod:`~sgbelief.query.referring.classes`). Assumptions: memberships of different nodes are independent;
the utterance names exactly one referent; the anchor is one node of the anchor class.

* Superlatives (closest, farthest; near and far read as the superlatives): for an anchor a, with
  the candidates ordered by distance to a, v is the referent iff v is a member and no nearer node
  is: ``P(v | a) = p_v * prod_{u nearer than v} (1 - p_u)``, divided by P(some member) =
  ``1 - prod_u (1 - p_u)``. With certain labels this is 1 for the nearest member, 0 otherwise.
* Every other relation R is a (soft) predicate ``s_v(a)`` in [0, 1] (a logistic step around
  Sr3D's thresholds; :mod:`~sgbelief.query.referring.geometry`). With ``w_v = p_v s_v``, v is *the*
  member satisfying R when it satisfies R and no other member does: ``P(v only) = w_v prod_{u != v}
  (1 - w_u)``. Conditioning on exactly one referent: ``P(v | a) = o_v / sum_u o_u``, ``o_v = w_v /
  (1 - w_v)``. With certain labels and one satisfying candidate this is 1 for it.
* Anchors (and fronts h): ``P(v) = sum_{a,h} pi(a,h) P(v | a,h)`` with ``pi(a,h) ∝ q_a prior(h | a)
  E(a,h)``, where ``E`` is the probability that the utterance is well formed under (a, h) -- that
  exactly one member satisfies R (P(some member) for superlatives). So an anchor or a front under
  which nothing, or several things, satisfy the relation loses weight: the anchor and the front the
  utterance presupposes are inferred with the referent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sgbelief.query.referring.allocentric import SectionConfig, front_hypotheses, section_occupancy
from sgbelief.query.referring.classes import Membership, NodeTable
from sgbelief.query.referring.geometry import between_measures, effective_distance, soft_above, vertical_measures
from sgbelief.query.referring.model import AnchorChoice, CandidateScore, ReferAnswer, ReferringQuery, Relation

__all__ = ["ReferConfig", "score_scene"]

_EPS = 1e-9


@dataclass(frozen=True)
class ReferConfig:
    """Thresholds of the relations (Sr3D's values, metres) and the widths of their soft steps."""

    touch: float = 0.15               # support: |bottom - top| at most this
    supported_overlap: float = 0.3    # support: footprint overlap over the supported object's footprint
    support_area_ratio: float = 1.5   # support: the supported footprint at most this times the supporter's
    vertical_gap: float = 0.06        # above / below: clear vertical gap at least this
    vertical_overlap: float = 0.2     # above / below: footprint overlap over either footprint
    between_hull: float = 0.51        # between: target footprint inside the anchors' hull
    between_anchor_overlap: float = 0.1   # between: at most this of the target over an anchor
    between_z: float = 0.2            # between: z-overlap with each anchor over the target's height
    section_occupancy: float = 0.5    # left/right/front/back: centre of the soft step on occupancy
    near_distance: float = 1.0        # near / far: reported against this distance (explain)
    superlative_gap: float = 0.2      # scene choice: Sr3D's margin of the nearest (farthest) over the runner-up
    width_ratio: float = 0.05         # soft-step widths: ratios
    width_metres: float = 0.03        # soft-step widths: metres
    width_occupancy: float = 0.12
    relaxed_vertical: float = 0.5     # weight of "over / under the anchor" when the stated vertical relation fails
    max_anchor_hypotheses: int = 64
    commit_tau: float = 0.5           # a belief counts towards class membership above this (the commit rule)
    sections: SectionConfig = field(default_factory=SectionConfig)


def _superlative(d: np.ndarray, p: np.ndarray, farthest: bool) -> tuple[np.ndarray, float]:
    """P(v is the nearest (farthest) member) for each candidate, and P(some member)."""
    order = np.lexsort((np.arange(len(d)), -d if farthest else d))
    out = np.zeros(len(d))
    none_before = 1.0
    for i in order.tolist():
        out[i] = p[i] * none_before
        none_before *= 1.0 - p[i]
    return out, 1.0 - none_before


def _unique(w: np.ndarray) -> tuple[np.ndarray, float]:
    """P(v is the only satisfying member | exactly one), and P(exactly one)."""
    w = np.clip(w, _EPS, 1.0 - 1e-7)
    odds = w / (1.0 - w)
    total = float(odds.sum())
    exactly_one = float(np.exp(np.sum(np.log1p(-w)))) * total
    return odds / total, exactly_one


def _vertical(rel: Relation, m: dict[str, np.ndarray], cfg: ReferConfig) -> np.ndarray:
    wr, wm = cfg.width_ratio, cfg.width_metres
    overlap = soft_above(np.maximum(m["i_target"], m["i_anchor"]), cfg.vertical_overlap, wr)
    if rel in (Relation.ON, Relation.ABOVE):
        relaxed = overlap * soft_above(m["gap_up"], -cfg.touch, wm)
    else:
        relaxed = overlap * soft_above(m["gap_down"], -cfg.touch, wm)
    if rel is Relation.ON:
        s = (soft_above(m["i_target"], cfg.supported_overlap, wr) * soft_above(-np.abs(m["gap_up"]), -cfg.touch, wm)
             * soft_above(-m["area_ratio"], -cfg.support_area_ratio, 3 * wr))
    elif rel is Relation.SUPPORTING:
        s = (soft_above(m["i_anchor"], cfg.supported_overlap, wr) * soft_above(-np.abs(m["gap_down"]), -cfg.touch, wm)
             * soft_above(-1.0 / np.maximum(m["area_ratio"], 1e-12), -cfg.support_area_ratio, 3 * wr))
    elif rel is Relation.ABOVE:
        s = soft_above(m["gap_up"], cfg.vertical_gap, wm) * overlap
    else:
        s = soft_above(m["gap_down"], cfg.vertical_gap, wm) * overlap
    return np.maximum(s, cfg.relaxed_vertical * relaxed)


def _measures_of(rel: Relation, table: NodeTable, cand: np.ndarray, anchors: tuple[int, ...],
                 cfg: ReferConfig, front: tuple[float, float] | None) -> tuple[np.ndarray | None, dict[str, np.ndarray]]:
    """(soft satisfaction s per candidate, or None for a superlative; the raw measures)."""
    lo, hi = table.lo[cand], table.hi[cand]
    a = anchors[0]
    if rel in (Relation.CLOSEST, Relation.NEAR, Relation.FARTHEST, Relation.FAR):
        return None, {"distance": effective_distance(lo, hi, table.lo[a], table.hi[a])}
    if rel is Relation.BETWEEN:
        b = anchors[1]
        m = between_measures(lo, hi, table.lo[a], table.hi[a], table.lo[b], table.hi[b])
        wr = cfg.width_ratio
        s = (soft_above(m["hull"], cfg.between_hull, 1.6 * wr)
             * soft_above(-m["over_a"], -cfg.between_anchor_overlap, 0.8 * wr)
             * soft_above(-m["over_b"], -cfg.between_anchor_overlap, 0.8 * wr)
             * soft_above(m["z_a"], cfg.between_z, wr) * soft_above(m["z_b"], cfg.between_z, wr))
        return s, m
    if rel.view_dependent:
        assert front is not None
        occ = section_occupancy(lo, hi, table.lo[a], table.hi[a], front, rel, cfg.sections)
        return soft_above(occ, cfg.section_occupancy, cfg.width_occupancy), {"occupancy": occ}
    m = vertical_measures(lo, hi, table.lo[a], table.hi[a])
    return _vertical(rel, m, cfg), m


def _anchor_sets(query: ReferringQuery, anchors: list[Membership], cap: int) -> list[tuple[tuple[int, ...], float]]:
    """Anchor hypotheses (node index tuples) with their membership weight, the most probable first."""
    if query.relation is Relation.BETWEEN:
        a, b = anchors
        sets = [((int(i), int(j)), float(pa * pb)) for i, pa in zip(a.index, a.p) for j, pb in zip(b.index, b.p) if i != j]
    else:
        sets = [((int(i),), float(pa)) for i, pa in zip(anchors[0].index, anchors[0].p)]
    sets.sort(key=lambda t: -t[1])
    return sets[:cap]


def _exactly_one(q: np.ndarray) -> float:
    """P(exactly one of independent members with probabilities q)."""
    q = np.clip(q, 0.0, 1.0 - 1e-12)
    return float(np.prod(1.0 - q) * np.sum(q / (1.0 - q)))


def _scene_evidence(rel: Relation, raw_total: float, priors: list[float], target: Membership,
                    anchors: list[Membership], meas_h: list[dict[str, np.ndarray]], weights: list[float],
                    cfg: ReferConfig) -> float:
    """How well a scene explains the utterance, to choose among scenes that all hold its classes:
    the mean over anchor hypotheses of P(well formed), times Sr3D's presuppositions -- a unique
    anchor (all but the support and vertical relations), and for a superlative at least two members
    of the target class and a clear winner (the runner-up ``gap`` metres behind)."""
    if math.isnan(raw_total) or not priors:
        return 0.0
    ev = raw_total / max(sum(priors), 1e-12)
    if rel.family in ("horizontal", "between", "allocentric"):
        for m in anchors:
            ev *= _exactly_one(m.p)
    if rel.family == "horizontal" and weights:
        if _exactly_one(target.p) + float(np.prod(1.0 - np.clip(target.p, 0.0, 1.0))) >= 1.0 - 1e-12:
            ev *= 0.05  # at most one member: Sr3D asks closest / farthest only among several
        d = meas_h[int(np.argmax(weights))].get("distance")
        if d is not None:
            ds = np.sort(d[target.p > 0.5])
            if rel in (Relation.FARTHEST, Relation.FAR):
                ds = ds[::-1]
            if len(ds) >= 2:
                ev *= float(soft_above(abs(ds[1] - ds[0]), cfg.superlative_gap, cfg.width_metres))
    return ev


def score_scene(table: NodeTable, scene: Any, query: ReferringQuery, target: Membership,
                anchors: list[Membership], cfg: ReferConfig) -> tuple[ReferAnswer, float]:
    """The answer in one scene, and the evidence sum_{a,h} q_a prior(h) E(a,h) (how well the scene
    explains the utterance; used to pick a scene when several hold the classes)."""
    rel = query.relation
    cand = target.index
    notes: list[str] = []
    hyps: list[tuple[tuple[int, ...], tuple[float, float] | None, float, str]] = []
    for nodes, q in _anchor_sets(query, anchors, cfg.max_anchor_hypotheses):
        if rel.view_dependent:
            for h in front_hypotheses(table, scene, nodes[0], cfg.sections):
                hyps.append((nodes, h.front, q * h.prior, h.note))
        else:
            hyps.append((nodes, None, q, ""))
    probs = np.zeros(len(cand))
    weights: list[float] = []
    per_h: list[np.ndarray] = []
    meas_h: list[dict[str, np.ndarray]] = []
    for nodes, front, prior, _ in hyps:
        p = target.p.copy()
        p[np.isin(cand, nodes)] = 0.0  # an anchor is not its own referent
        s, meas = _measures_of(rel, table, cand, nodes, cfg, front)
        if s is None:
            cond, evidence = _superlative(meas["distance"], p, rel in (Relation.FARTHEST, Relation.FAR))
            cond = cond / evidence if evidence > 0 else cond
        else:
            meas = {**meas, "satisfies": s}
            cond, evidence = _unique(p * s)
        weights.append(prior * evidence)
        per_h.append(cond)
        meas_h.append(meas)
    total = raw_total = float(sum(weights))
    if hyps and total <= 0.0:
        notes.append("no anchor hypothesis explains the utterance; anchors weighted by membership alone")
        weights = [h[2] for h in hyps]
        total = float(sum(weights))
    for w, cond in zip(weights, per_h):
        probs += (w / total) * cond if total > 0 else 0.0
    z = float(probs.sum())
    if z > 0:
        probs /= z
    order = sorted(range(len(cand)), key=lambda i: (-probs[i], table.nodes[cand[i]].__repr__()))
    best_h = int(np.argmax(weights)) if weights else -1
    candidates = []
    for i in order:
        measures: dict[str, float] = {}
        if best_h >= 0:
            measures = {k: float(v[i]) for k, v in meas_h[best_h].items()}
            if rel in (Relation.NEAR, Relation.FAR) and "distance" in measures:
                measures["within_near_distance"] = float(measures["distance"] <= cfg.near_distance)
        candidates.append(CandidateScore(table.nodes[cand[i]], float(probs[i]), float(target.p[i]), measures))
    anchor_choices = []
    for k in sorted(range(len(hyps)), key=lambda k: -weights[k])[:10]:
        nodes, front, _, note = hyps[k]
        anchor_choices.append(AnchorChoice(tuple(table.nodes[n] for n in nodes), weights[k] / total if total else 0.0,
                                           front, note))
    if target.tier != "exact" or any(a.tier != "exact" for a in anchors):
        tiers = ", ".join(f"{name}: {m.tier}" for name, m in zip((query.target, *query.anchors), (target, *anchors)))
        notes.append(f"class match tiers ({tiers})")
    ranked = tuple((c.node, c.probability) for c in candidates)
    evidence = _scene_evidence(rel, raw_total, [h[2] for h in hyps], target, anchors, meas_h, weights, cfg)
    return ReferAnswer(query, scene, ranked, tuple(candidates), tuple(anchor_choices), tuple(notes)), evidence
