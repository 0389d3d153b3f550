"""ConceptGraphs drop-in backend: belief fusion instead of majority-vote labels.

Usage in a ConceptGraphs run script (after its imports)::

    from sgbelief.adapters.conceptgraphs import ConceptGraphsBackend
    backend = ConceptGraphsBackend("comod", context="yolo-world-v8l/gsa-v1")
    backend.install()          # or: with backend.patch(): main()

The vocabulary is the class list the run loads (or ``class_names=``); ``uninstall()`` prints what the
backend did per class (``backend.summary()``).

torch and open3d are imported only when ConceptGraphs data is touched.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "ConceptGraphsBackend": "sgbelief.adapters.conceptgraphs.backend",
    "ClassVocabulary": "sgbelief.adapters.conceptgraphs.vocab",
    "normalise_class_name": "sgbelief.adapters.conceptgraphs.vocab",
    "IdentityMap": "sgbelief.adapters.conceptgraphs.identity",
    "BeliefLabelledObject": "sgbelief.adapters.conceptgraphs.generation_base",
    "MapBeliefs": "sgbelief.adapters.conceptgraphs.map_beliefs",
    "MainGeneration": "sgbelief.adapters.conceptgraphs.generation_main",
    "AliDevGeneration": "sgbelief.adapters.conceptgraphs.generation_ali_dev",
    "make_functions": "sgbelief.adapters.conceptgraphs.functions",
    "Patcher": "sgbelief.adapters.conceptgraphs.patching",
    "DetectionList": "sgbelief.adapters.conceptgraphs.standins",
    "MapObjectList": "sgbelief.adapters.conceptgraphs.standins",
    "RestrictedUnpickler": "sgbelief.adapters.conceptgraphs.unpickler",
    "UnsafePickleError": "sgbelief.adapters.conceptgraphs.unpickler",
    "load_cg_result": "sgbelief.adapters.conceptgraphs.unpickler",
    "import_result": "sgbelief.adapters.conceptgraphs.importer",
    "BackendSummary": "sgbelief.adapters.conceptgraphs.summary",
    "ClassSummary": "sgbelief.adapters.conceptgraphs.summary",
    "ConceptGraphsNotFoundError": "sgbelief.adapters.conceptgraphs.patching",
    "LabelResolver": "sgbelief.adapters.conceptgraphs.channel_labels",
    "PointCloudChannel": "sgbelief.adapters.conceptgraphs.channels",
    "scannet_mesh_channel": "sgbelief.adapters.conceptgraphs.channels",
    "LabelImageChannel": "sgbelief.fusion.channel",
    "LowConfidenceWarning": "sgbelief.errors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
