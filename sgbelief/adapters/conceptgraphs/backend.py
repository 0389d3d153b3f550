"""ConceptGraphsBackend: belief fusion behind ConceptGraphs' mapping functions.

The public face of the adapter. It builds the parts from names (operator, vocabulary, graph), keeps
the belief bookkeeping of :class:`~.map_beliefs.MapBeliefs`, and installs the replacement functions
of the detected ConceptGraphs generation through :class:`~.patching.Patcher`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from sgbelief._fast import gc as gc_tuning
from sgbelief.adapters.conceptgraphs.functions import GenerationFunctions, make_functions
from sgbelief.adapters.conceptgraphs.map_beliefs import (
    DEFAULT_LABEL_KEY,
    BackendSummary,
    Claim,
    DetectionLabelFn,
    MapBeliefs,
)
from sgbelief.adapters.conceptgraphs.patching import Patcher
from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary

__all__ = ["DEFAULT_LABEL_KEY", "BackendSummary", "Claim", "ConceptGraphsBackend", "DetectionLabelFn"]


class ConceptGraphsBackend(MapBeliefs):
    """Routes every ConceptGraphs detection into a :class:`~sgbelief.graph.scene_graph.SceneGraph`.

    Args:
        operator: operator name (``comod``, ``cal``, ``majority``, ...) or a FusionOperator instance.
        vocabulary: a :class:`ClassVocabulary`, a path to ``sgbelief/configs/conceptgraphs/*.yaml`` or None
            (shipped ScanNet vocabulary).
        context: the context tag kappa (detector / VLM and prompt version) of every event.
        channel: optional geometric channel: a GeometricChannel (``label(node, t)``), or a callable
            ``fn(detection, node, t) -> str | None``.  A detection's own ``label_key`` entry wins.
        graph: the scene graph to fill (default: a new one); one handed in may already hold evidence.
        operator_config: the operator's config (a name, a YAML path, a dict) when ``operator`` is a name.
        geometric_evidence: how ``comod`` reads the geometric label when ``operator`` is a name:
            ``"label"`` also observes the predicates the label itself asserts, so an object whose
            class no detection named can still be labelled (docs/method.md §3; the label rule keeps
            such predicates as a fallback), ``"verdict"`` or ``"none"``. None (default): the
            ``operator_config``'s own ``geometric_evidence`` when it sets one, else ``"label"``
            (the operator default elsewhere is ``"verdict"``).
        label_key: detection-dict key holding a per-detection geometric label (popped from the dict
            before ConceptGraphs' merge sees it, since the original merges reject unknown keys).
        unknown_label / unknown_class_id: label written when no predicate commits.
        tau / tau_t: commit threshold and targeting-mass threshold (default: the operator config).
        on_filter: ``"mark"`` (node kept with ``cg_filtered=True``) or ``"remove"``.
        confidence_map: optional map of the detector's raw confidence before it enters an event.
        gc_checkpoints: call :meth:`gc_checkpoint` once per frame (after the patched per-frame
            merge), so CPython's full collections never rescan the whole map.
        label_rule: the class written when the committed predicate covers several class names
            (``is_table_or_desk``: table, desk): ``"most_frequent"`` (default: the name detected most
            often on this object, ties to the first seen), ``"first"`` (the first name detected), or a
            mapping predicate -> class name (e.g. ``{"is_table_or_desk": "table"}``; predicates not in
            it fall back to most frequent). A mapped name that is a known class id keeps that id.
    """

    def __init__(
        self,
        operator: str | Any = "comod",
        vocabulary: ClassVocabulary | str | Path | None = None,
        context: str = "conceptgraphs",
        channel: Any = None,
        *,
        graph: Any = None,
        operator_config: Any = None,
        label_key: str = DEFAULT_LABEL_KEY,
        unknown_label: str = "unknown",
        unknown_class_id: int = -1,
        tau: float | None = None,
        tau_t: float | None = None,
        on_filter: str = "mark",
        confidence_map: Callable[[float], float] | None = None,
        class_names: Sequence[str] | None = None,
        gc_checkpoints: bool = False,
        label_rule: str | Mapping[str, str] = "most_frequent",
        geometric_evidence: str | None = None,
    ) -> None:
        from sgbelief.api.scene_graph import SceneGraph

        if isinstance(vocabulary, ClassVocabulary):
            vocab = vocabulary
        elif vocabulary is None:
            vocab = ClassVocabulary.default()
        else:
            vocab = ClassVocabulary.from_yaml(vocabulary)
        if isinstance(operator, str):
            from sgbelief.api.operators import make_operator

            op = make_operator(operator, config=_with_geometric_evidence(operator_config, geometric_evidence),
                               vocabulary=vocab.table())
            self.operator_name = operator
        else:
            op = operator
            self.operator_name = type(operator).__name__
        super().__init__(
            op, vocab, graph if graph is not None else SceneGraph(), seed_from_graph=graph is not None,
            context=context, channel=channel, label_key=label_key, unknown_label=unknown_label,
            unknown_class_id=unknown_class_id, tau=tau, tau_t=tau_t, on_filter=on_filter,
            confidence_map=confidence_map, class_names=class_names, label_rule=label_rule)
        self._patcher: Patcher | None = None
        self.gc_checkpoints = bool(gc_checkpoints)
        self._froze = False

    # ------------------------------------------------------------------ garbage collector
    def gc_checkpoint(self) -> None:
        """Collect the cyclic garbage made since the last checkpoint, then freeze what survives.

        CPython's generation-2 collection re-traverses every tracked object; a map holds several per
        provenance entry (live for T_prov steps), so its pauses grow with objects x history (about
        3 s at 5,000 objects x 500 detections). Frozen objects (``gc.freeze()``) are skipped, and
        reference counting still frees them; each checkpoint only scans what is new since the
        previous one. Cycles that become garbage after being frozen wait for ``gc.unfreeze()``
        (done by :meth:`uninstall`). See docs/performance.md, "ConceptGraphs per-frame cost".
        """
        gc_tuning.checkpoint()
        self._froze = True

    def end_frame(self) -> None:
        """Called by the patched per-frame merge functions: the per-frame housekeeping hook."""
        if self.gc_checkpoints:
            self.gc_checkpoint()

    # ------------------------------------------------------------------ functions & patching
    def functions(self, generation: str = "main") -> GenerationFunctions:
        """ConceptGraphs-signature functions for ``generation`` (``main`` or ``ali-dev``): those
        installed when the backend is installed for that generation, else new ones with sgbelief's
        own geometry."""
        patcher = self._patcher
        if patcher is not None and patcher.functions is not None and patcher.generation == generation:
            return patcher.functions
        return make_functions(self, generation)

    def install(self, *modules: Any, generation: str | None = None, fix_list_kwargs: bool = True) -> None:
        """Swap the belief-routing functions into ConceptGraphs' (already imported) modules."""
        if self._patcher is not None:
            raise RuntimeError("backend already installed; call uninstall() first")
        patcher = Patcher(self, extra_modules=modules, generation=generation, fix_list_kwargs=fix_list_kwargs)
        patcher.install()
        self._patcher = patcher
        self.active = True

    def uninstall(self) -> None:
        """Restore every name swapped by :meth:`install` (and unfreeze what :meth:`gc_checkpoint` froze)."""
        if self._patcher is not None:
            self._patcher.uninstall()
            self._patcher = None
        if self._froze:
            gc_tuning.release_checkpoints()
            self._froze = False

    @contextlib.contextmanager
    def patch(self, *modules: Any, generation: str | None = None, fix_list_kwargs: bool = True) -> Iterator[ConceptGraphsBackend]:
        """Context manager form of :meth:`install` / :meth:`uninstall`."""
        self.install(*modules, generation=generation, fix_list_kwargs=fix_list_kwargs)
        try:
            yield self
        finally:
            self.uninstall()

    @property
    def generation(self) -> str | None:
        return None if self._patcher is None else self._patcher.generation

    def log_to_rerun(self, frame: int, *, recording: Any = None, prefix: str = "sgbelief", timeline: str = "t") -> int:
        """Log the map as it stands after ``frame`` into the current rerun recording (or ``recording``):
        boxes with committed label and P, every belief's mean, the claims refused in this frame.
        Needs ``sgbelief[rerun]``; see docs/visualisation.md. Returns the number of entities logged."""
        from sgbelief.viz.rerun_log import log_frame

        return log_frame(self.graph, frame, recording=recording, prefix=prefix, tau=self.tau, timeline=timeline)

    def save(self, path: str | Path) -> Path:
        """Save the belief graph (SceneGraph JSON)."""
        from sgbelief.graph.persistence import save_graph

        return save_graph(self.graph, path)


def _with_geometric_evidence(config: Any, geometric_evidence: str | None) -> Any:
    """The backend's operator config: ``config`` (anything
    :func:`~sgbelief.fusion.config.resolve_config` reads; None: the shipped default) with
    ``geometric_evidence`` set, validated. None sets ``"label"`` unless ``config`` sets the key itself."""
    from sgbelief.fusion.config import OperatorConfig, resolve_config

    base = OperatorConfig.default() if config is None else resolve_config(config)
    if geometric_evidence is None:
        if config is not None and "geometric_evidence" in base.model_fields_set:
            return base
        geometric_evidence = "label"
    return OperatorConfig.from_mapping({**base.model_dump(), "geometric_evidence": geometric_evidence},
                                       source="ConceptGraphsBackend(geometric_evidence=...)")
