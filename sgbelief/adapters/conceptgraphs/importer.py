"""Offline retrofit: replay a saved ConceptGraphs map's per-detection history through an operator."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sgbelief.adapters.conceptgraphs.geometry import geometry_summary
from sgbelief.errors import FormatError


@dataclass
class ImportSummary:
    """What :func:`import_result` did."""

    n_objects: int
    n_detections: int
    n_events: int
    n_unknown: int = 0  #: objects left unknown (nothing commits)
    labels: dict[str, dict[str, Any]] = field(default_factory=dict)  # node -> {majority, belief, ...}


def _objects_of(results: Any, path: Any) -> tuple[list[tuple[str, dict]], list[str] | None]:
    if isinstance(results, list):
        groups = [("cg", results)]
        class_names = None
    elif isinstance(results, Mapping):
        if "objects" not in results:
            raise FormatError("missing key 'objects'", path=path)
        groups = [("cg", results["objects"] or [])]
        if results.get("bg_objects"):
            groups.append(("cg-bg", results["bg_objects"]))
        names = results.get("class_names")
        class_names = [str(n) for n in names] if isinstance(names, Sequence) and not isinstance(names, str) else None
    else:
        raise FormatError(f"expected a dict or list of objects, got {type(results).__name__}", path=path)
    out: list[tuple[str, dict]] = []
    for prefix, objs in groups:
        if not isinstance(objs, list):
            raise FormatError(f"'objects' must be a list, got {type(objs).__name__}", path=path)
        for i, obj in enumerate(objs):
            if not isinstance(obj, Mapping) or "class_id" not in obj:
                raise FormatError(f"object {i}: expected a dict with 'class_id'", path=path)
            out.append((f"{prefix}-{i}", dict(obj)))
    return out, class_names


def import_result(results: Any, backend: Any, *, path: Any = None, progress: Any = None) -> ImportSummary:
    """Replay every object's (class, confidence, frame) history, in frame order, into ``backend``.

    ``progress``, if given, is called as ``progress(done, total)`` every 256 detections and at the end."""
    objects, class_names = _objects_of(results, path)
    if class_names:
        backend.class_names.update(dict(enumerate(class_names)))
    learn = getattr(backend, "learn_class_list", None)
    if learn is not None and not backend.class_list_known:
        # the default vocabulary: the map's class list, else every class name its objects claim
        if class_names:
            learn(class_names, source="the map's class_names")
        else:
            seen = {c.class_name: None for _, obj in objects for c in backend.claims_of(obj)}
            learn(list(seen), source="the map's detected class names")
    claims: list[tuple[int, int, int, str, dict]] = []
    for order, (node, obj) in enumerate(objects):
        centroid, bbox = geometry_summary(obj)
        backend.graph.add_node(node, centroid=centroid, bbox=bbox, source="conceptgraphs",
                               cg_index=order, cg_id=str(obj.get("id")) if obj.get("id") is not None else None)
        backend.identity.rebind(obj, node)
        for k, claim in enumerate(backend.claims_of(obj)):
            single = {"class_id": [claim.class_id], "class_name": [claim.class_name],
                      "conf": [claim.confidence], "image_idx": [claim.t]}
            for key in ("pcd", "pcd_np"):  # a point-cloud channel labels every claim from the object's points
                if obj.get(key) is not None:
                    single[key] = obj[key]
            claims.append((claim.t, order, k, node, single))
    claims.sort(key=lambda c: (c[0], c[1], c[2]))
    n_events = 0
    for i, (_t, _o, _k, node, single) in enumerate(claims):
        n_events += backend.route_detection(single, {node: 1.0})
        if progress is not None and (i + 1) % 256 == 0:
            progress(i + 1, len(claims))
    if progress is not None:
        progress(len(claims), len(claims))
    summary = ImportSummary(n_objects=len(objects), n_detections=len(claims), n_events=n_events)
    for node, obj in objects:
        ids = [c.class_id for c in backend.claims_of(obj)]
        names = Counter(c.class_name for c in backend.claims_of(obj))
        hit = backend.committed_class(node)
        summary.labels[node] = {
            "majority": names.most_common(1)[0][0] if names else None,
            "majority_class_id": Counter(ids).most_common(1)[0][0] if ids else None,
            "belief": backend.unknown_label if hit is None else hit[1],
            "predicate": backend.committed_predicate(node),
            "num_detections": len(ids),
        }
        backend.graph.nx.nodes[node]["label"] = summary.labels[node]["belief"]
        summary.n_unknown += int(hit is None)
    return summary


def import_file(path: str | Path, backend: Any, *, progress: Any = None) -> ImportSummary:
    """Load ``path`` with the restricted unpickler and import it (``progress``: see import_result)."""
    from sgbelief.adapters.conceptgraphs.unpickler import load_cg_result

    return import_result(load_cg_result(path), backend, path=path, progress=progress)
