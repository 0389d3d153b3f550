"""Drop-in replacements for ConceptGraphs' mapping functions, one set per code generation.

``main`` (classic ``cfslam_pipeline_batch.py``): functions take ``cfg`` first
(:class:`~.generation_main.MainGeneration`). ``ali-dev`` (``streamlined_mapping.py`` /
``rerun_realtime_mapping.py``): explicit keyword params (:class:`~.generation_ali_dev.AliDevGeneration`).
Each function keeps ConceptGraphs' signature and return contract, does the geometric work through the
original function when one is passed in (else through :mod:`.geometry`), and routes every
detection's claim into the backend's belief graph.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from sgbelief.adapters.conceptgraphs.generation_ali_dev import AliDevGeneration
from sgbelief.adapters.conceptgraphs.generation_base import BeliefLabelledObject, GenerationFunctions
from sgbelief.adapters.conceptgraphs.generation_main import MainGeneration

if TYPE_CHECKING:  # pragma: no cover
    from sgbelief.adapters.conceptgraphs.map_beliefs import MapBeliefs

__all__ = ["GENERATIONS", "AliDevGeneration", "BeliefLabelledObject", "GenerationFunctions", "MainGeneration",
           "make_functions"]

#: the ConceptGraphs code generations and their replacement functions
GENERATIONS: dict[str, type[GenerationFunctions]] = {"main": MainGeneration, "ali-dev": AliDevGeneration}


def make_functions(backend: MapBeliefs, generation: str, originals: Mapping[str, Any] | None = None,
                   helpers: Mapping[str, Any] | None = None) -> GenerationFunctions:
    """The replacement functions for ``generation`` ('main' or 'ali-dev'), as attributes.

    ``originals``: ConceptGraphs' own functions by name (the geometric merge and filter go through
    them); ``helpers``: ConceptGraphs objects called through (``compute_overlap_matrix[_general]``,
    ``tracker``). :class:`~sgbelief.adapters.conceptgraphs.patching.Patcher` passes what it captured.
    """
    cls = GENERATIONS.get(generation)
    if cls is None:
        raise ValueError("generation must be 'main' or 'ali-dev'")
    return cls(backend, originals, helpers)
