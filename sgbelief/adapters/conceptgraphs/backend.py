"""ConceptGraphsBackend: belief fusion behind ConceptGraphs' mapping functions.

The public face of the adapter. It builds the parts from names (operator, vocabulary, graph), keeps
the belief bookkeeping of :class:`~.map_beliefs.MapBeliefs`, and installs the replacement functions
of the detected ConceptGraphs generation through :class:`~.patching.Patcher`.
"""

from __future__ import annotations

import contextlib
import sys
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

from sgbelief._fast import gc as gc_tuning
from sgbelief.adapters.conceptgraphs.functions import GenerationFunctions, make_functions
from sgbelief.adapters.conceptgraphs.map_beliefs import (
    DEFAULT_LABEL_KEY,
    BackendSummary,
    Claim,
    DetectionLabelFn,
    MapBeliefs,
)
from sgbelief.adapters.conceptgraphs.patching import ConceptGraphsNotFoundError, Patcher
from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary, normalise_class_name

__all__ = ["DEFAULT_LABEL_KEY", "BackendSummary", "Claim", "ConceptGraphsBackend", "ConceptGraphsNotFoundError",
           "DetectionLabelFn"]

#: classes ConceptGraphs treats as background: no predicate (they stay channel labels)
BACKGROUND = ("wall", "floor", "ceiling")


class ConceptGraphsBackend(MapBeliefs):
    """Routes every ConceptGraphs detection into a :class:`sgbelief.SceneGraph`.

    The default vocabulary is the class list the run uses: ``class_names=``, else the list
    ConceptGraphs loads (read when :meth:`install` has patched its loaders: ``create_or_load_colors``
    / ``gobs_to_detection_list`` on ``main``, ``ObjectClasses`` on ``ali-dev``). Every class is its
    own, mutually exclusive predicate; the taxonomy merges only synonyms (couch / sofa), ``merge=``
    also merges its groups of kinds (table / desk). Should a claim arrive before any class list is
    known, the vocabulary is derived from the class names detected so far, with a warning.

    Args:
        operator: operator name (``comod``, ``cal``, ``majority``, ...) or a FusionOperator instance.
        vocabulary: None (default: the run's class list, see above), a :class:`ClassVocabulary`, or a
            file / shipped name of ``sgbelief/configs/conceptgraphs`` (``"scannet"``: the closed,
            hand-written ScanNet table; ``"scannet200"``, ``"coco80"``, ``"replica"``).
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
        unknown_label / unknown_class_id: label written when no predicate commits (``abstain``,
            the default) or when the claimed classes tie.
        abstain: write ``unknown_label`` whenever no predicate commits (default True); False writes
            the claimed class of highest probability instead (every object gets a class).
        tau / tau_t: commit threshold and targeting-mass threshold (default: the operator config).
        on_filter: ``"mark"`` (node kept with ``cg_filtered=True``) or ``"remove"``.
        confidence_map: optional map of the detector's raw confidence before it enters an event:
            sgbelief reads a confidence as the probability that the detection is right, so for a
            detector whose scores are not, :class:`~sgbelief.calibration.scores.ScoreCalibration`
            fitted on annotated detections. Without one the operator learns how far the scores sit
            below how often claims agree and reads them that much higher (``calibration.consensus.method:
            agreement_shift``, the backend's default; the summary prints the shift); a detector whose
            scores do not show which of its claims agree has every claim read at one level (a rank
            test on the map, ``score_test_level``; the summary says so). With the raw
            reading configured (``method: none``), a run with most claims below 0.5 and no channel
            warns (:class:`~sgbelief.errors.LowConfidenceWarning`).
        class_names: the run's class list, by class id, or its file / shipped name (``"replica"``,
            ``"scannet200"``) (default: the list ConceptGraphs loads).
        taxonomy: the taxonomy of synonyms / groups / hypernyms the open vocabulary uses
            (``"indoor"``, a YAML path or a :class:`~sgbelief.fusion.open_vocab.Taxonomy`).
        merge: also merge the taxonomy's groups of kinds: True for every group, or the group
            predicates (``["is_table_or_desk"]``). Default False: the class list's classes stay separate.
        ignore: classes that get no predicate (background); ConceptGraphs' own background classes are added.
        print_summary: :meth:`uninstall` prints :meth:`summary` (to this stream; True: stderr; False: never).
        gc_checkpoints: call :meth:`gc_checkpoint` once per frame (after the patched per-frame
            merge), so CPython's full collections never rescan the whole map.
        label_rule: the class written when the committed predicate covers several class names
            (``is_table_or_desk``: table, desk, when merged): ``"most_frequent"`` (default: the label
            the geometric channel gave most often on this object when it names one of them, else the
            name detected most often, ties to the first seen), ``"first"`` (the first name detected), or a
            mapping predicate -> class name (e.g. ``{"is_table_or_desk": "table"}``; predicates not in
            it fall back to most frequent). A mapped name that is a known class id keeps that id.
        targeting: where a matched detection's claims go. ``"merge"`` (default): whole to the object
            ConceptGraphs merges the detection's geometry into (its association argmax), so each
            object's beliefs are about the detections it is made of. ``"spread"``: over every
            candidate above the threshold, T(v) proportional to its positive association score
            (docs/conceptgraphs.md, "Evidence routing").
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
        class_names: Sequence[str] | str | Path | None = None,
        gc_checkpoints: bool = False,
        label_rule: str | Mapping[str, str] = "most_frequent",
        abstain: bool = True,
        geometric_evidence: str | None = None,
        taxonomy: Any = "indoor",
        merge: bool | Iterable[str] = False,
        ignore: Iterable[str] = BACKGROUND,
        print_summary: bool | TextIO = True,
        targeting: str = "merge",
    ) -> None:
        from sgbelief.api.scene_graph import SceneGraph

        self.taxonomy = taxonomy
        self.merge = merge if isinstance(merge, bool) else list(merge)
        self.ignore = list(ignore)
        self.print_summary = print_summary
        #: where the vocabulary came from: "vocabulary=", "class_names=", a ConceptGraphs function, or None
        self.vocabulary_source: str | None = None
        if isinstance(class_names, (str, Path)):  # a class-list file or shipped name ("replica")
            from sgbelief.fusion.open_vocab import resolve_class_list

            class_names = list(resolve_class_list(class_names).names)
        elif class_names is not None:
            class_names = [str(n) for n in class_names]
        if isinstance(vocabulary, ClassVocabulary):
            vocab: ClassVocabulary | None = vocabulary
        elif vocabulary is not None:
            vocab = ClassVocabulary.from_yaml(vocabulary)
        elif class_names is not None:
            vocab = self._open_vocabulary(list(class_names), ())
        else:
            vocab = None
        if vocab is not None:
            self.vocabulary_source = "vocabulary=" if vocabulary is not None else "class_names="
        self._growing = False
        if isinstance(operator, str):
            from sgbelief.api.operators import make_operator

            op = make_operator(operator, config=_with_geometric_evidence(operator_config, geometric_evidence),
                               vocabulary=vocab.table() if vocab is not None else None)
            self.operator_name = operator
        else:
            op = operator
            self.operator_name = type(operator).__name__
        super().__init__(
            op, vocab, graph if graph is not None else SceneGraph(), seed_from_graph=graph is not None,
            context=context, channel=channel, label_key=label_key, unknown_label=unknown_label,
            unknown_class_id=unknown_class_id, tau=tau, tau_t=tau_t, on_filter=on_filter,
            confidence_map=confidence_map, class_names=class_names, label_rule=label_rule, abstain=abstain,
            targeting=targeting)
        self._share_table = isinstance(operator, str) or getattr(op, "vocabulary", None) is None
        self._patcher: Patcher | None = None
        self.gc_checkpoints = bool(gc_checkpoints)
        self._froze = False
        if vocab is not None:
            self._check_channel_classes()

    # ------------------------------------------------------------------ vocabulary
    def _open_vocabulary(self, names: list[str], background: Iterable[str]) -> ClassVocabulary:
        ignore = list(dict.fromkeys([*self.ignore, *background]))
        return ClassVocabulary.open_vocabulary(names, taxonomy=self.taxonomy, ignore=ignore, merge=self.merge)

    @property
    def class_list_known(self) -> bool:
        """Whether the vocabulary is settled (given, or learnt from the run's class list)."""
        return self.vocabulary is not None and not self._growing

    def learn_class_list(self, names: Sequence[str], *, background: Iterable[str] = (), source: str = "") -> None:
        """The class list the run uses (called by the patched ConceptGraphs loaders): it becomes the
        vocabulary unless one was given. A given ``class_names=`` that differs is warned about."""
        names = [str(n) for n in names]
        if self.class_list_known:
            given = getattr(self.vocabulary, "class_names", None)
            if self.vocabulary_source == "class_names=" and given is not None and \
                    [normalise_class_name(n) for n in given] != [normalise_class_name(n) for n in names]:
                warnings.warn(f"ConceptGraphs runs with a class list ({source}: {len(names)} classes) other than "
                              f"the class_names= given ({len(given)}); the backend keeps class_names=",
                              stacklevel=3)
            return
        if not names:
            return
        vocab = self._open_vocabulary(names, background)
        vocab.name = f"{len(names)} classes from {source or 'the run'}"
        self.set_vocabulary(vocab)
        self._growing = False
        self.vocabulary_source = source or "learn_class_list"
        self.class_names.update(dict(enumerate(names)))
        self._check_channel_classes()

    def vocabulary_needed(self, class_name: str) -> ClassVocabulary:
        """No class list known when a claim arrives: derive the vocabulary from the class names
        detected so far (warned once); a new name re-derives it."""
        vocab = self.vocabulary
        if self._growing and vocab is not None and vocab.class_names:
            known = list(vocab.class_names)
        else:
            known = list(dict.fromkeys(self.class_names.values()))
        if not self._growing:
            warnings.warn("ConceptGraphsBackend: no class list is known (pass class_names=, or call install() "
                          "before ConceptGraphs loads its classes); the vocabulary is derived from the class "
                          "names detected so far", stacklevel=4)
            self._growing = True
            self.vocabulary_source = "detected class names"
        keys = {normalise_class_name(n) for n in known}
        if normalise_class_name(class_name) in keys:
            if vocab is not None and vocab.class_names is not None and len(vocab.class_names) == len(known):
                return vocab
            return self._open_vocabulary(known, ())
        return self._open_vocabulary([*known, class_name], ())

    def _check_channel_classes(self) -> None:
        """A channel that declares its class list (``LabelImageChannel(classes=...)``) is checked
        against the vocabulary: none matching raises, names matching nothing are warned about."""
        check = getattr(self.channel, "check_vocabulary", None)
        if check is not None and self.table is not None:
            check(self.table)

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
        """Called by the patched per-frame merge functions: the per-frame housekeeping hook (the
        frame's queued events applied and :meth:`MapBeliefs.end_frame`'s checks, then the
        garbage-collector checkpoint if enabled)."""
        super().end_frame()
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
        """Swap the belief-routing functions into ConceptGraphs' modules (imported here when the run
        script has not imported them yet). Raises :class:`ConceptGraphsNotFoundError` naming what is
        missing when they cannot be imported: the backend is never active with nothing patched."""
        if self._patcher is not None:
            raise RuntimeError("backend already installed; call uninstall() first")
        patcher = Patcher(self, extra_modules=modules, generation=generation, fix_list_kwargs=fix_list_kwargs)
        try:
            patcher.install()
        except BaseException:
            patcher.uninstall()
            self.active = False
            raise
        self._patcher = patcher
        self.active = True

    def uninstall(self) -> None:
        """Restore every name swapped by :meth:`install` (and unfreeze what :meth:`gc_checkpoint` froze),
        then print :meth:`summary` (``print_summary``)."""
        if self._patcher is not None:
            self._patcher.uninstall()
            self._patcher = None
            stream = sys.stderr if self.print_summary is True else self.print_summary
            if stream and self.routed_detections:
                print(self.summary().format(), file=stream)
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
        """Save the belief graph (SceneGraph JSON), and :meth:`summary` as JSON beside it
        (``<stem>.summary.json``)."""
        import json

        from sgbelief.graph.persistence import atomic_write_text, save_graph

        self.flush()
        out = save_graph(self.graph, path)
        atomic_write_text(summary_path(out), json.dumps(self.summary().to_dict(), indent=1))
        return out


def summary_path(map_path: str | Path) -> Path:
    """Where the backend's summary of a map saved at ``map_path`` goes: ``<stem>.summary.json`` beside it."""
    p = Path(map_path)
    return p.with_name(f"{p.name.split('.')[0]}.summary.json")


def _with_geometric_evidence(config: Any, geometric_evidence: str | None) -> Any:
    """The backend's operator config: ``config`` (anything
    :func:`~sgbelief.fusion.config.resolve_config` reads; None: the shipped default) with
    ``geometric_evidence`` set, validated. None sets ``"label"`` unless ``config`` sets the key itself."""
    from sgbelief.fusion.config import OperatorConfig, resolve_config

    base = OperatorConfig.default() if config is None else resolve_config(config)
    own = base.model_fields_set if config is not None else set()
    update: dict[str, Any] = {}
    if geometric_evidence is not None or "geometric_evidence" not in own:
        update["geometric_evidence"] = geometric_evidence if geometric_evidence is not None else "label"
    if "exclusive_evidence" not in own:
        # the label rule already reads one class among the exclusive ones; the coupling's entries
        # reach only rival pairs that exist when a claim commits, and with the early claims'
        # small calibrated weights that order effect cost label accuracy in ConceptGraphs' own
        # loop with no channel (docs/conceptgraphs.md, "Labels out"): off unless the config sets it
        update["exclusive_evidence"] = "none"
    if "calibration" not in own and base.calibration.consensus.method == "dawid_skene":
        # the map-wide Dawid-Skene consensus needs many elements per class; a ConceptGraphs map
        # holds tens of objects, most claims land on short-lived objects the mapper later filters or
        # merges, and the fit explains them as "none of these": without a channel that cost 0.4-0.6
        # label accuracy in ConceptGraphs' own loop (docs/conceptgraphs.md, "Labels out"). What such
        # a map does identify is one parameter per detector: how far its scores sit from how often
        # its claims agree (agreement_shift, docs/method.md §8). The summary says which.
        cal = base.calibration.model_dump()
        cal["consensus"] = {**cal["consensus"], "method": "agreement_shift"}
        update["calibration"] = cal
        if "contested_labels" not in own and base.contested_labels == "consensus":
            # with no consensus to ask, contested_labels: consensus refuses every contradicted claim:
            # say so in the settings the summary prints
            update["contested_labels"] = "refuse"
    if not update:
        return base
    return OperatorConfig.from_mapping({**base.model_dump(), **update},
                                       source="ConceptGraphsBackend(geometric_evidence=...)")
