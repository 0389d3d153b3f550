"""The cold monolithic compound prompt of the simulated suites: Table 4's baseline channel.

Instead of one belief per component, the foundation model is asked the whole compound at once
("is this a parked car near a crossing?") about the crop of a visible element, once per named
compound, and answers with one confidence. The error model (docs/simulation.md, "Monolithic
compound channel") is derived from the component models, not fitted to any outcome:

* the **object part** (the compound's VLM-typed predicate phi) is read exactly as a component claim
  is: z_phi = mu_{y'} + u_{v,phi} + sigma_phi e, with y' the truth flipped with probability
  ``confident_wrong``, u_{v,phi} the element's *own* persistent offset (the one its component
  claims carry, so an element the model keeps misreading is misread here too) and e ~ N(0, 1);
* each **relation** g (``is_near_road_px``, ``is_stationary``, ...) has no map geometry behind it:
  the model reads it from the same crop with the latent model ``monolithic.relation`` (default
  ``vlm.default``, the simulator's model of a predicate without a spec of its own), a persistent
  per-(element, relation) offset and fresh noise; a negated literal reads -z_g;
* the **conjunction**: a reader that answers each part with probability sigmoid(z) and multiplies,
  z_Q = logit(prod_l sigmoid(z_l)); the confidence is the profile's distortion of phi,
  c = sigmoid(gain_phi z_Q + bias_phi), so a model swap changes c and nothing else.

When every part but the relations is certain (z_phi -> +-inf), z_Q is the relations' own reading:
the compound's own error rate, nothing inherited (tested by hand-computed cases).

The verification label of a claim is the geometric channel's label of the element in the crop's
frame (its largest unoccluded view, :class:`sgbelief.eval.simulate.View`); the file
``monolithic.jsonl`` (docs/formats.md) holds one record per (visible element, compound).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from sgbelief.errors import ConfigError, FormatError
from sgbelief.eval.sim_config import LatentSpec, SimConfig
from sgbelief.graph.persistence import atomic_write_text
from sgbelief.query.named import NamedQuery

__all__ = ["CompoundSpec", "MonolithicClaim", "MonolithicChannel", "MonolithicRecord", "literal_latent",
           "compound_latent", "generate_claims", "monolithic_channel", "write_monolithic", "read_monolithic",
           "MONOLITHIC_FORMAT", "MONOLITHIC_STREAM"]

MONOLITHIC_FORMAT = "sgbelief.monolithic"
#: the child of ``SeedSequence(seed)`` the channel draws from (simulate() uses children 0-4)
MONOLITHIC_STREAM = 5
_CONF_DECIMALS = 6
_S_MAX = -1e-15  # log prod sigmoid is clipped below 0 so that z_Q stays finite (|z_Q| <= ~34.5)


@dataclass(frozen=True)
class CompoundSpec:
    """A compound as the monolithic prompt sees it: one VLM-typed predicate and its relations."""

    key: str
    predicate: str
    relations: tuple[tuple[str, bool], ...]  # (geometric predicate, negated)

    @classmethod
    def from_named(cls, nq: NamedQuery) -> CompoundSpec:
        objs = [lit for lit in nq.belief if not lit.negated]
        if len(objs) != 1 or len(nq.belief) != 1:
            raise ValueError(f"query {nq.name!r}: the monolithic channel needs exactly one positive VLM-typed "
                             f"predicate, got {[str(b) for b in nq.belief]}")
        return cls(nq.name, objs[0].name, tuple((lit.name, lit.negated) for lit in nq.geometric))


def literal_latent(spec: LatentSpec, y: int, offset: float, noise: float, flipped: bool) -> float:
    """The latent reading of one part: mu_{y'} + offset + sigma * noise, y' = y flipped if ``flipped``
    (the simulator's component equation, parametric)."""
    return (spec.mu_pos if (bool(y) != flipped) else spec.mu_neg) + offset + spec.sigma * noise


def compound_latent(parts: Sequence[float]) -> float:
    """z_Q = logit(prod sigmoid(z_l)) for the literals' readings z_l (negated literals already
    mirrored); computed in log space, finite for finite inputs."""
    s = math.fsum(-np.logaddexp(0.0, -z) for z in parts)
    s = min(s, _S_MAX)
    return s - math.log(-math.expm1(s))


def _compound_latent_array(parts: Sequence[np.ndarray]) -> np.ndarray:
    s = np.zeros_like(parts[0])
    for z in parts:
        s -= np.logaddexp(0.0, -z)
    s = np.minimum(s, _S_MAX)
    return s - np.log(-np.expm1(s))


@dataclass(frozen=True)
class MonolithicClaim:
    """One answer of the monolithic prompt, independent of the profile and of the channel."""

    node: str
    query: str
    predicate: str
    t: int
    z: float  # latent compound score; confidence = sigmoid(gain_phi * z + bias_phi)
    y: int  # truth of the compound on the element
    labels: Mapping[str, str | None]  # geometric channel -> label of the element in the crop's frame


def generate_claims(
    nodes: Sequence[str],
    compounds: Sequence[CompoundSpec],
    *,
    truth: Callable[[str, str], int],
    relation_truth: Callable[[str, str], bool | None],
    config: SimConfig,
    rng: np.random.Generator,
    offsets: Mapping[tuple[str, str], float] | None = None,
    times: Mapping[str, int] | None = None,
    labels: Mapping[str, Mapping[str, str | None]] | None = None,
) -> list[MonolithicClaim]:
    """The monolithic answers for every (node, compound), compound-major, nodes in the given order.

    ``truth(node, predicate)``: 1/0 of a VLM-typed predicate; ``relation_truth(node, name)``: the
    geometry's value (None: undefined, read and scored as false); ``offsets``: the component
    claims' persistent offsets u_{v,phi} (missing ones are drawn from N(0, element_sigma^2)).
    Draw order (deterministic): per first use of a predicate or relation, its n offsets; per
    compound, the object's flips and noise, then each relation's flips and noise."""
    n = len(nodes)
    if n == 0:
        return []
    vlm, mono = config.vlm, config.monolithic
    offsets = offsets or {}
    persistent: dict[str, np.ndarray] = {}

    def offsets_of(name: str, shared: bool) -> np.ndarray:
        if name not in persistent:
            fresh = rng.normal(0.0, vlm.element_sigma, n) if vlm.element_sigma > 0 else np.zeros(n)
            if shared:
                fresh = np.asarray([offsets.get((v, name), float(f)) for v, f in zip(nodes, fresh)])
            persistent[name] = fresh
        return persistent[name]

    def reading(spec: LatentSpec, y: np.ndarray, off: np.ndarray) -> np.ndarray:
        flip = rng.random(n) < spec.confident_wrong
        e = rng.standard_normal(n)
        return np.where(y.astype(bool) != flip, spec.mu_pos, spec.mu_neg) + off + spec.sigma * e

    out: list[MonolithicClaim] = []
    for comp in compounds:
        y_obj = np.asarray([int(truth(v, comp.predicate)) for v in nodes], dtype=int)
        parts = [reading(vlm.spec(comp.predicate), y_obj, offsets_of(comp.predicate, True))]
        holds = y_obj.astype(bool)
        for name, negated in comp.relations:
            vals = [relation_truth(v, name) for v in nodes]
            y_g = np.asarray([bool(x) for x in vals], dtype=int)
            z_g = reading(mono.relation_spec(name, vlm), y_g, offsets_of(name, False))
            parts.append(-z_g if negated else z_g)
            holds &= np.asarray([x is not None and bool(x) != negated for x in vals], dtype=bool)
        z = _compound_latent_array(parts)
        for k, v in enumerate(nodes):
            out.append(MonolithicClaim(v, comp.key, comp.predicate, int((times or {}).get(v, 0)),
                                       round(float(z[k]), 6), int(holds[k]), dict((labels or {}).get(v, {}))))
    return out


def _sigmoid(x: float) -> float:
    if x >= 0:
        return 1.0 / (1.0 + math.exp(-x))
    e = math.exp(x)
    return e / (1.0 + e)


class MonolithicRecord(NamedTuple):
    """One line of ``monolithic.jsonl``: the prompt's answer about one element and one compound
    (lightweight, like :class:`~sgbelief.eval.formats.EventRecord`; a file is validated by
    :func:`read_monolithic` through :class:`_RecordModel`)."""

    node: str
    query: str
    t: int
    confidence: float
    context: str
    geometric: str | None


class _RecordModel(BaseModel):
    """The validation model of one ``monolithic.jsonl`` line (the file boundary)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    node: str = Field(min_length=1)
    query: str = Field(min_length=1, description="named-query key")
    t: int = Field(ge=0, description="frame of the crop")
    confidence: float = Field(ge=0.0, le=1.0)
    context: str = Field(min_length=1, description="the model (kappa)")
    geometric: str | None = Field(description="the geometric channel's label of the element in that frame")


@dataclass
class MonolithicChannel:
    """The claims of one suite, viewable under any profile and geometric channel."""

    config: SimConfig
    claims: list[MonolithicClaim]

    def records(self, profile: str | None = None, channel: str | None = None) -> list[MonolithicRecord]:
        prof = self.config.vlm.profiles[profile or self.config.profile]
        ch = channel or self.config.channel
        out = []
        for cl in self.claims:
            d = prof.distortion(cl.predicate)
            c = round(_sigmoid(d.gain * cl.z + d.bias), _CONF_DECIMALS)
            out.append(MonolithicRecord(cl.node, cl.query, cl.t, c, prof.context, cl.labels.get(ch)))
        return out

    def write(self, path: str | os.PathLike[str], profile: str | None = None, channel: str | None = None) -> Path:
        return write_monolithic(path, self.records(profile, channel))


def monolithic_channel(suite: Any, queries: Mapping[str, NamedQuery] | None = None) -> MonolithicChannel:
    """The monolithic prompt over a :class:`~sgbelief.eval.simulate.SimulatedSuite`: every element
    with an unoccluded view (``suite.views``) x every named compound of the suite's query set
    (``monolithic.queries``, default the vocabulary's), drawn from the suite seed's own stream."""
    from sgbelief.api.scene_graph import SceneGraph
    from sgbelief.eval.formats import node_attributes
    from sgbelief.query.engine import QueryEngine
    from sgbelief.query.named import named_queries

    cfg: SimConfig = suite.config
    if queries is None:
        queries = named_queries(cfg.monolithic.queries or Path(cfg.vocabulary).stem)
    compounds = [CompoundSpec.from_named(nq) for nq in queries.values()]
    named = {g for comp in compounds for g, _neg in comp.relations}
    for g in cfg.monolithic.relations:
        if g not in named:
            raise ConfigError(f"monolithic.relations.{g}: not a relation of any compound asked "
                              f"(relations: {sorted(named)})")
    rel_config = replace(next(iter(queries.values())).config, use_committed_labels=False)
    graph = SceneGraph(create_nodes=True)
    for nid, info in suite.nodes.nodes.items():
        graph.add_node(nid, **node_attributes(info))
    engine = QueryEngine(graph, config=rel_config, require_evidence=False)
    nodes = sorted(v for v in suite.views if v in suite.nodes.nodes)
    rng = np.random.default_rng(np.random.SeedSequence(suite.seed).spawn(MONOLITHIC_STREAM + 1)[MONOLITHIC_STREAM])
    claims = generate_claims(
        nodes, compounds, truth=lambda v, p: suite.truth.get(v, {}).get(p, 0),
        relation_truth=engine.geometric, config=cfg, rng=rng, offsets=suite.offsets,
        times={v: suite.views[v].t for v in nodes}, labels={v: suite.views[v].labels for v in nodes})
    return MonolithicChannel(cfg, claims)


# ----------------------------------------------------------------------------------- file format
def write_monolithic(path: str | os.PathLike[str], records: Iterable[MonolithicRecord]) -> Path:
    """Write ``monolithic.jsonl`` atomically: a header line, then one record per line."""
    lines = [json.dumps({"format": MONOLITHIC_FORMAT, "version": 1}) + "\n"]
    lines += [json.dumps(r._asdict(), separators=(",", ":"), allow_nan=False, ensure_ascii=False) + "\n"
              for r in records]
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(p, lines)
    return p


def read_monolithic(path: str | os.PathLike[str]) -> list[MonolithicRecord]:
    """Read and validate ``monolithic.jsonl``; a bad line raises :class:`FormatError` naming the
    file, the line and the field. A (node, query) pair may appear once."""
    p = Path(path)
    out: list[MonolithicRecord] = []
    seen: set[tuple[str, str]] = set()
    try:
        fh = open(p, "rb")
    except FileNotFoundError:
        raise FormatError("no such file", path=p) from None
    with fh:
        first = True
        for lineno, raw in enumerate(fh, 1):
            if not raw.strip():
                continue
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as exc:
                raise FormatError(f"not UTF-8 text (byte {exc.start})", path=p, line=lineno) from None
            if first:
                first = False
                try:
                    head = json.loads(text)
                except json.JSONDecodeError:
                    head = None
                if isinstance(head, dict) and "format" in head:
                    if head.get("format") != MONOLITHIC_FORMAT or head.get("version") != 1:
                        raise FormatError(f"header: expected format {MONOLITHIC_FORMAT!r} version 1, got "
                                          f"{head.get('format')!r} version {head.get('version')!r}", path=p, line=lineno)
                    continue
            try:
                m = _RecordModel.model_validate_json(text)
            except ValidationError as exc:
                err = exc.errors()[0]
                field = ".".join(str(x) for x in err["loc"]) or "(line)"
                raise FormatError(f"field '{field}': {err['msg']}", path=p, line=lineno) from None
            rec = MonolithicRecord(m.node, m.query, m.t, m.confidence, m.context, m.geometric)
            key = (rec.node, rec.query)
            if key in seen:
                raise FormatError(f"node {rec.node!r}, query {rec.query!r}: answered twice", path=p, line=lineno)
            seen.add(key)
            out.append(rec)
    return out
