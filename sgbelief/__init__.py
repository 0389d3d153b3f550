"""sgbelief: calibrated Beta beliefs for open-vocabulary 3D scene graphs.

The public API is loaded lazily (PEP 562) so that ``import sgbelief`` stays fast:
numpy/scipy/networkx/scikit-learn are imported only when a name that needs them
is first used, and torch/open3d only inside the adapters that use them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from sgbelief.version import __version__

# public name -> module that defines it
_EXPORTS: dict[str, str] = {
    "BetaBelief": "sgbelief.graph.belief",
    "ProvenanceStore": "sgbelief.graph.provenance",
    "EntryStatus": "sgbelief.graph.provenance",
    "SceneGraph": "sgbelief.api.scene_graph",
    "EvidenceEvent": "sgbelief.fusion.events",
    "GeometricChannel": "sgbelief.fusion.channel",
    "RecordedChannel": "sgbelief.fusion.channel",
    "Verdict": "sgbelief.fusion.compatibility",
    "SubsumptionTable": "sgbelief.fusion.compatibility",
    "OperatorConfig": "sgbelief.fusion.config",
    "FusionOperator": "sgbelief.fusion.protocol",
    "UpdateReport": "sgbelief.fusion.protocol",
    "make_operator": "sgbelief.api.operators",
    "OPERATOR_NAMES": "sgbelief.fusion.registry",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'sgbelief' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from sgbelief.fusion.channel import GeometricChannel, RecordedChannel
    from sgbelief.fusion.compatibility import SubsumptionTable, Verdict
    from sgbelief.fusion.config import OperatorConfig
    from sgbelief.fusion.events import EvidenceEvent
    from sgbelief.fusion.protocol import FusionOperator, UpdateReport
    from sgbelief.api.operators import make_operator
    from sgbelief.fusion.registry import OPERATOR_NAMES
    from sgbelief.graph.belief import BetaBelief
    from sgbelief.graph.provenance import EntryStatus, ProvenanceStore
    from sgbelief.api.scene_graph import SceneGraph
