"""Evaluating compound queries over a scene graph: probabilities, ranking, explanations.

Probability of a compound (independence assumption across components)::

    P(v, q) = prod_{belief literals b} f_b(v)  *  prod_{geometric literals g} 1[g(v) holds]

with ``f_b = p`` for a plain and ``1 - p`` for a negated belief literal, ``p`` the posterior mean
of the node's Beta belief (``graph.probability``). Geometric literals come from the relation
registry and are authoritative indicators (0 or 1; a negated one is ``1 - indicator``); a
geometric predicate that cannot be decided (missing attribute, value None) gives 0 in *either*
polarity. A node is retrieved when ``P > tau`` (strictly above; default 0.5) -- the commit rule of
``SceneGraphModel.committed()`` and ``sgbelief inspect``, so a node at the prior 0.5 is never retrieved.

Candidates: with ``require_evidence=True`` (default) only nodes that have evidence on every
*positive* belief literal are scored -- a node nobody has made a claim about stays at the prior
mean 0.5 and would otherwise be "retrieved" at tau = 0.5. A negated belief literal without
evidence contributes ``1 - 0.5 = 0.5``.

Per-component reuse: a :class:`QueryEngine` caches every belief probability and geometric value
it reads, so evaluating a batch of compounds that share components reads each (node, predicate)
once. Nothing is written to the graph.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from sgbelief.errors import SgbeliefWarning
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.query.language import Compound, Literal, QueryPredicateError, QuerySyntaxError, parse
from sgbelief.query.named import UnknownNamedQueryError, find_named_query, suggest_named_queries
from sgbelief.query.relations import DEFAULT_REGISTRY, GeometryContext, RelationConfig, RelationRegistry

__all__ = ["Component", "Match", "MissingGeometryWarning", "QueryResult", "QueryEngine", "missing_attributes", "run_query"]

BELIEF = "belief"
GEOMETRIC = "geometric"


class MissingGeometryWarning(SgbeliefWarning):
    """A query's geometric predicate cannot be evaluated on some candidates: they lack the node
    attributes it needs (a map saved without geometry), so it counts as false for them."""


def missing_attributes(attrs: Mapping[str, Any], needs: Iterable[str]) -> list[str]:
    """The needs of a geometric predicate that a node's attributes do not meet. A need is an
    attribute name, alternatives joined by ``|``, ``name?`` (optional) or ``scene`` (the other
    nodes of the map, not an attribute of this one). An attribute is looked up as the relations
    read it (:meth:`GeometryContext.attr`): at the top level, else inside the node's nested
    ``attributes`` dict (a nodes.json entry's)."""
    inner = attrs.get("attributes")
    nested: Mapping[str, Any] = inner if isinstance(inner, Mapping) else {}
    out = []
    for need in needs:
        alternatives = need.split("|")
        if need.endswith("?") or "scene" in alternatives:
            continue
        if not any(a in attrs or nested.get(a) is not None for a in alternatives):
            out.append(need)
    return out


@dataclass(frozen=True)
class Component:
    """One literal's contribution for one node.

    ``value``: the belief probability (belief) or the predicate's truth value (geometric, None
    when undecidable); ``factor``: what enters the product (p, 1-p, 1 or 0)."""

    name: str
    kind: str
    negated: bool
    value: float | bool | None
    factor: float
    evidence: bool = True

    @property
    def literal(self) -> str:
        return ("!" if self.negated else "") + self.name

    def to_dict(self) -> dict[str, Any]:
        return {"predicate": self.name, "kind": self.kind, "negated": self.negated,
                "value": self.value, "factor": self.factor, "evidence": self.evidence}

    def describe(self) -> str:
        if self.kind == BELIEF:
            ev = "" if self.evidence else " (no evidence: prior)"
            if self.negated:
                return f"{self.literal} = 1 - {self.value:.3f} = {self.factor:.3f}  [belief]{ev}"
            return f"{self.literal} = {self.factor:.3f}  [belief]{ev}"
        shown = "undecidable (missing attribute)" if self.value is None else str(bool(self.value)).lower()
        return f"{self.literal} = {self.factor:.0f}  [geometric: {shown}]"


@dataclass(frozen=True)
class Match:
    """A scored node: its compound probability and the per-component breakdown."""

    node: Any
    probability: float
    components: tuple[Component, ...]
    retrieved: bool

    def explain(self) -> str:
        """Multi-line explanation: the product and one line per component."""
        head = f"{self.node}: P = {self.probability:.4f} ({'retrieved' if self.retrieved else 'not retrieved'})"
        return "\n".join([head] + ["  " + c.describe() for c in self.components])

    def to_dict(self) -> dict[str, Any]:
        return {"node": self.node, "probability": self.probability, "retrieved": self.retrieved,
                "components": [c.to_dict() for c in self.components]}


@dataclass
class QueryResult:
    """Retrieved nodes ranked by probability (descending; ties by node id)."""

    compound: Compound
    tau: float
    matches: list[Match]
    n_candidates: int
    name: str | None = None
    kinds: dict[str, str] = field(default_factory=dict)
    #: nodes with P > tau before ``limit`` cut the list (None: count the retrieved matches listed)
    total_retrieved: int | None = None

    @property
    def n_retrieved(self) -> int:
        """How many candidates are retrieved (P > tau), whatever ``limit`` / ``include_all`` listed."""
        if self.total_retrieved is not None:
            return self.total_retrieved
        return sum(1 for m in self.matches if m.retrieved)

    def __iter__(self) -> Iterator[Match]:
        return iter(self.matches)

    def __len__(self) -> int:
        return len(self.matches)

    def __getitem__(self, i: int) -> Match:
        return self.matches[i]

    @property
    def nodes(self) -> list[Any]:
        return [m.node for m in self.matches]

    @property
    def expression(self) -> str:
        return str(self.compound)

    def to_dict(self) -> dict[str, Any]:
        return {"query": self.name, "expression": self.expression, "tau": self.tau,
                "components": [{"predicate": lit.name, "negated": lit.negated, "kind": self.kinds.get(lit.name)}
                               for lit in self.compound.literals],
                "n_candidates": self.n_candidates, "n_retrieved": self.n_retrieved, "n_listed": len(self.matches),
                "results": [m.to_dict() for m in self.matches]}

    def table(self, limit: int | None = None) -> str:
        """Plain-text table: rank, node, P, then one column per component factor."""
        lits = list(self.compound.literals)
        head = ["rank", "node", "P"] + [f"{lit}[{'b' if self.kinds.get(lit.name) == BELIEF else 'g'}]" for lit in lits]
        rows = []
        for r, m in enumerate(self.matches[:limit] if limit else self.matches, 1):
            rows.append([str(r), str(m.node), f"{m.probability:.4f}"] + [
                f"{c.factor:.3f}" if c.kind == BELIEF else ("?" if c.value is None else f"{c.factor:.0f}")
                for c in m.components])
        widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h) for i, h in enumerate(head)]
        fmt = lambda row: "  ".join(x.ljust(w) if i == 1 else x.rjust(w) for i, (x, w) in enumerate(zip(row, widths)))  # noqa: E731
        listed = len(self.matches)
        shown = f"; {listed} listed" if listed != self.n_retrieved else ""
        title = f"{self.name + ': ' if self.name else ''}{self.expression}   (tau = {self.tau}, " \
                f"{self.n_retrieved} retrieved (P > tau) of {self.n_candidates} candidates{shown}; " \
                f"b = belief, g = geometric)"
        out = [title, fmt(head)] + [fmt(r) for r in rows]
        if limit and listed > limit:
            out.append(f"... {listed - limit} more")
        return "\n".join(out)


class QueryEngine:
    """Answers compound queries over one graph with per-batch caches of every component read.

    ``registry``: geometric predicates (default :data:`DEFAULT_REGISTRY`); ``config``: their
    thresholds; ``tau``: retrieval threshold; ``require_evidence``: see the module docstring;
    ``probability``: ``f(node, predicate) -> p`` used for belief literals, node by node (default:
    the graph's own beliefs, read in bulk through ``graph.probabilities``; pass
    ``operator.probability`` bound to the graph for an operator's recalibrated probability);
    ``use_precomputed``: a node attribute
    ``geometric_predicates = {name: bool}`` (simulated ``nodes.json``) overrides the registry.
    The caches assume the graph does not change while the engine is in use (call :meth:`clear`
    after updates)."""

    def __init__(self, graph: SceneGraphModel, *, registry: RelationRegistry | None = None,
                 config: RelationConfig | None = None, tau: float = 0.5,
                 require_evidence: bool = True, probability: Callable[[Any, str], float] | None = None,
                 use_precomputed: bool = True) -> None:
        if not 0.0 <= tau <= 1.0:
            raise ValueError(f"tau must be in [0, 1], got {tau!r}")
        self.graph = graph
        self.probability_fn = probability if probability is not None else graph.probability
        #: the bulk read of belief literals: the graph's own when no ``probability`` is given
        self._read_probabilities: Callable[[list[Any], str], list[float]] = (
            graph.probabilities if probability is None else _per_node(probability))
        self.use_precomputed = use_precomputed
        self.registry = registry if registry is not None else DEFAULT_REGISTRY
        self.config = config or RelationConfig()
        self.tau = tau
        self.require_evidence = require_evidence
        self.clear()

    def clear(self) -> None:
        """Drop all caches (after the graph changed)."""
        self.ctx = GeometryContext(self.graph, self.config)
        self._prob: dict[str, dict[Any, float]] = {}
        self._evidence: dict[str, set[Any]] = {}
        self._geo: dict[str, dict[Any, bool | None]] = {}
        self._known_beliefs: set[str] | None = None
        self.belief_reads = 0
        self.geometric_evals = 0

    # -- compilation -------------------------------------------------------------------------
    def known_belief_predicates(self) -> set[str]:
        if self._known_beliefs is None:
            known = set(self.graph.predicates())
            if self.graph.vocabulary:
                known |= set(self.graph.vocabulary)
            self._known_beliefs = known
        return self._known_beliefs

    def compile(self, expr: str | Compound) -> tuple[Compound, dict[str, str]]:
        """Parse (if needed) and resolve each literal to 'geometric' (registry) or 'belief'."""
        compound = parse(expr) if isinstance(expr, str) else expr
        kinds: dict[str, str] = {}
        for lit in compound.literals:
            if lit.name in self.registry:
                kinds[lit.name] = GEOMETRIC
            elif lit.name in self.known_belief_predicates():
                kinds[lit.name] = BELIEF
            else:
                known = sorted(self.known_belief_predicates()) + self.registry.names()
                raise QueryPredicateError(lit.name, known, compound.expression, max(lit.position, 0))
        return compound, kinds

    # -- cached component reads --------------------------------------------------------------
    def evidence_nodes(self, predicate: str) -> set[Any]:
        """Nodes with at least one evidence entry on ``predicate``."""
        s = self._evidence.get(predicate)
        if s is None:
            s = self._evidence[predicate] = set(self.graph.provenance.nodes_with(predicate))
        return s

    def belief(self, node: Any, predicate: str) -> float:
        """The node's probability for ``predicate`` (``probability_fn``), cached."""
        return self.belief_many(predicate, (node,))[0]

    def geometric(self, node: Any, name: str) -> bool | None:
        """The geometric predicate ``name`` on the node, cached (see :meth:`geometric_many`)."""
        return self.geometric_many(name, (node,))[0]

    def belief_many(self, predicate: str, nodes: Iterable[Any]) -> list[float]:
        """:meth:`belief` of each node, in order (each node read once, then cached). When the
        engine reads the graph's own beliefs, the uncached nodes go through the graph's bulk
        ``probabilities`` (same values and errors as ``probability``, the predicate checked once)."""
        cache = self._prob.setdefault(predicate, {})
        nodes = nodes if isinstance(nodes, (list, tuple)) else list(nodes)
        todo = [n for n in dict.fromkeys(nodes) if n not in cache]
        if todo:
            values = self._read_probabilities(todo, predicate)
            for n, p in zip(todo, values):
                cache[n] = float(p)
            self.belief_reads += len(todo)
        return [cache[n] for n in nodes]

    def geometric_many(self, name: str, nodes: Iterable[Any]) -> list[bool | None]:
        """The geometric predicate ``name`` on each node, in order (cached): a precomputed
        ``geometric_predicates[name]`` node attribute when ``use_precomputed``, else the registry's."""
        cache = self._geo.setdefault(name, {})
        attrs_of = self.ctx.attrs
        pred = None
        out: list[bool | None] = []
        for node in nodes:
            if node in cache:
                out.append(cache[node])
                continue
            v: bool | None = None
            pre = attrs_of(node).get("geometric_predicates") if self.use_precomputed else None
            if pre is not None and isinstance(pre, Mapping) and name in pre and pre[name] is not None:
                v = bool(pre[name])
            else:
                if pred is None:
                    pred = self.registry.get(name)
                v = pred(self.ctx, node)
            cache[node] = v
            self.geometric_evals += 1
            out.append(v)
        return out

    def preload_geometric(self, name: str, values: Mapping[Any, bool | None]) -> None:
        """Seed the cache of geometric predicate ``name`` (e.g. values computed on a ground-truth
        copy of the map, shared by several operators' graphs)."""
        self._geo.setdefault(name, {}).update(values)

    # -- scoring -----------------------------------------------------------------------------
    def candidates(self, compound: Compound, kinds: Mapping[str, str], nodes: Iterable[Any] | None = None) -> list[Any]:
        """Nodes scored for ``compound`` (see ``require_evidence``), in graph order."""
        pool = list(self.graph.nodes()) if nodes is None else list(nodes)
        if self.require_evidence:
            for lit in compound.literals:
                if kinds[lit.name] == BELIEF and not lit.negated:
                    ev = self.evidence_nodes(lit.name)
                    pool = [n for n in pool if n in ev]
        return pool

    def score(self, node: Any, compound: Compound, kinds: Mapping[str, str], *, prune: bool = False,
              tau: float | None = None) -> Match | None:
        """Score one node: P(v, q) as in the module docstring, beliefs first, then geometry, each in
        literal order; with ``prune`` return None as soon as P < tau is certain."""
        scored = self.score_many((node,), compound, kinds, prune=prune, tau=tau)
        return scored[0] if scored else None

    def score_many(self, nodes: Sequence[Any], compound: Compound, kinds: Mapping[str, str], *,
                   prune: bool = False, tau: float | None = None) -> list[Match]:
        """:meth:`score` of each node (pruned ones left out), in order. Works one literal at a time
        over the nodes still in the running (beliefs first, then geometry, each in literal order),
        so a node's product is formed in the same order and reads only what it needs."""
        tau = self.tau if tau is None else tau
        lits: Sequence[Literal] = compound.literals
        n = len(nodes)
        prob = [1.0] * n
        alive = list(range(n))
        # beliefs first (cheap), then geometry, each in literal order; a literal's values by position
        steps = [k for k, lit in enumerate(lits) if kinds[lit.name] == BELIEF]
        steps += [k for k, lit in enumerate(lits) if kinds[lit.name] == GEOMETRIC]
        values: dict[int, dict[int, Any]] = {}
        for k in steps:
            lit = lits[k]
            if not alive:
                break
            at = [nodes[i] for i in alive]
            if kinds[lit.name] == BELIEF:
                got: list[Any] = self.belief_many(lit.name, at)
                factors = [1.0 - p if lit.negated else p for p in got]
            else:
                got = self.geometric_many(lit.name, at)
                neg = lit.negated
                factors = [0.0 if v is None else float(v != neg) for v in got]
            values[k] = dict(zip(alive, got))
            for i, f in zip(alive, factors):
                prob[i] *= f
            if prune:  # factors are <= 1: once P <= tau it stays there
                alive = [i for i in alive if prob[i] > tau]
        order = {lit.name: i for i, lit in enumerate(lits)}
        rank = order.__getitem__
        evidence = {lits[k].name: self.evidence_nodes(lits[k].name) for k in steps if kinds[lits[k].name] == BELIEF}
        out: list[Match] = []
        for i in alive:
            node = nodes[i]
            comps: list[Component] = []
            for k in steps:
                lit = lits[k]
                v = values[k][i]
                if kinds[lit.name] == BELIEF:
                    comps.append(Component(lit.name, BELIEF, lit.negated, v, 1.0 - v if lit.negated else v,
                                           node in evidence[lit.name]))
                else:
                    comps.append(Component(lit.name, GEOMETRIC, lit.negated, v,
                                           0.0 if v is None else float(v != lit.negated)))
            comps.sort(key=lambda c: rank(c.name))
            out.append(Match(node, prob[i], tuple(comps), prob[i] > tau))
        return out

    def evaluate(self, expr: str | Compound, *, tau: float | None = None, nodes: Iterable[Any] | None = None,
                 include_all: bool = False, limit: int | None = None, name: str | None = None) -> QueryResult:
        """Ranked retrieval for one compound. ``include_all`` also lists non-retrieved candidates
        (fully scored, no pruning); ``limit`` keeps the top k."""
        tau = self.tau if tau is None else tau
        compound, kinds = self.compile(expr)
        pool = self.candidates(compound, kinds, nodes)
        self._warn_missing_geometry(compound, kinds, pool)
        matches = [m for m in self.score_many(pool, compound, kinds, prune=not include_all, tau=tau)
                   if include_all or m.retrieved]
        matches.sort(key=lambda m: (-m.probability, str(m.node)))
        n_retrieved = sum(1 for m in matches if m.retrieved)
        if limit is not None:
            matches = matches[:limit]
        return QueryResult(compound, tau, matches, len(pool), name=name, kinds=dict(kinds), total_retrieved=n_retrieved)

    def _warn_missing_geometry(self, compound: Compound, kinds: Mapping[str, str], pool: Sequence[Any]) -> None:
        """Say when a geometric predicate cannot hold on some candidates for want of geometry."""
        node_attrs = self.graph.nx.nodes
        for lit in compound.literals:
            if kinds[lit.name] != GEOMETRIC:
                continue
            needs = self.registry.get(lit.name).needs
            # as geometric_many reads them: a precomputed value first, then the node's attributes
            lacking = [missing_attributes(node_attrs[n], needs) for n in pool
                       if n in node_attrs and not self._precomputed(node_attrs[n], lit.name)]
            n_lacking = sum(1 for m in lacking if m)
            if n_lacking:
                wanted = sorted({need for m in lacking for need in m})
                warnings.warn(MissingGeometryWarning(
                    f"{lit.name}: {n_lacking} of {len(pool)} candidate nodes lack the attribute(s) "
                    f"{', '.join(wanted)} it needs, so the query cannot retrieve them (was the map saved "
                    "without node geometry? replay --save-graph keeps it when the log has a nodes.json)"),
                    stacklevel=3)

    def _precomputed(self, attrs: Mapping[str, Any], name: str) -> bool:
        """Whether :meth:`geometric_many` takes ``name``'s value from the node's precomputed
        ``geometric_predicates`` rather than from the registry."""
        pre = attrs.get("geometric_predicates") if self.use_precomputed else None
        return isinstance(pre, Mapping) and pre.get(name) is not None

    def evaluate_many(self, exprs: Mapping[str, str | Compound] | Iterable[str | Compound], **kw: Any) -> dict[str, QueryResult]:
        """Evaluate a batch sharing this engine's caches; keys are the names (or expressions)."""
        items = exprs.items() if isinstance(exprs, Mapping) else ((str(e), e) for e in exprs)
        return {k: self.evaluate(e, name=k if isinstance(exprs, Mapping) else None, **kw) for k, e in items}

    def probabilities(self, expr: str | Compound, nodes: Iterable[Any] | None = None) -> dict[Any, float]:
        """P(node, compound) for every candidate (no pruning)."""
        compound, kinds = self.compile(expr)
        return {m.node: m.probability for m in self.score_many(self.candidates(compound, kinds, nodes), compound, kinds)}

    def explain(self, expr: str | Compound, node: Any) -> Match:
        """Full breakdown for one node (whether or not it is a candidate)."""
        compound, kinds = self.compile(expr)
        m = self.score(node, compound, kinds)
        assert m is not None
        return m


def run_query(graph: SceneGraphModel, expr: str | Compound, tau: float = 0.5, registry: RelationRegistry | None = None, *,
              config: RelationConfig | None = None, require_evidence: bool = True,
              include_all: bool = False, limit: int | None = None) -> QueryResult:
    """Answer one compound query: ``expr`` is an expression, a :class:`Compound`, or the name /
    title of a named query (``sgbelief/configs/queries/*.yaml``; its ``relations`` thresholds apply unless
    ``config`` is given). Returns a ranked, self-explaining :class:`QueryResult`."""
    name = None
    if isinstance(expr, str):
        nq = find_named_query(expr)
        if nq is not None:
            name, expr = nq.name, nq.compound
            if config is None:
                config = nq.config
        else:
            _check_not_a_mistyped_name(expr)
    engine = QueryEngine(graph, registry=registry, config=config, tau=tau, require_evidence=require_evidence)
    return engine.evaluate(expr, include_all=include_all, limit=limit, name=name)


def _check_not_a_mistyped_name(expr: str) -> None:
    """Words with no operator that do not parse ("car near unicorn") were meant as a named query:
    say there is no such query and suggest the closest ones, instead of a syntax error."""
    if any(ch in expr for ch in "&|!()~") or len(expr.split()) < 2:
        return
    try:
        parse(expr)
    except QuerySyntaxError:
        raise UnknownNamedQueryError(expr.strip(), suggest_named_queries(expr)) from None


def _per_node(probability: Callable[[Any, str], float]) -> Callable[[list[Any], str], list[float]]:
    """The bulk read made of a per-node ``probability(node, predicate)``."""

    def read(nodes: list[Any], predicate: str) -> list[float]:
        return [probability(n, predicate) for n in nodes]

    return read
