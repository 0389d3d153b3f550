"""Real detector confidences (COCO val, netcal examples) shipped in ``sgbelief/data/detector_confidences``.

Each record is one detection: image index, COCO category id, score in [0, 1] and whether it matched
a ground-truth box of its class (1 = true positive).  The files are flat ``.npz`` archives opened
with ``allow_pickle=False``; see the README next to them for attribution and licence.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sgbelief.errors import FormatError
from sgbelief.resources import data_path

__all__ = [
    "DetectorRecords",
    "AVAILABLE_RECORDS",
    "COCO_TO_PREDICATE",
    "available_records",
    "load_detector_records",
    "split_half",
    "predicate_pool",
]

AVAILABLE_RECORDS = ("rfcn-resnet-101-iou-0.60", "ssd-resnet-50-v1-iou-0.60")

# COCO category id -> predicates it grounds (documented in docs/simulation.md).
COCO_TO_PREDICATE: dict[int, tuple[str, ...]] = {
    3: ("is_car",),  # car
    6: ("is_car",),  # bus
    8: ("is_car",),  # truck
    1: ("is_pedestrian",),  # person
    13: ("is_traffic_sign",),  # stop sign
    10: ("is_traffic_sign", "is_traffic_light"),  # traffic light (no COCO "traffic sign" class)
    2: ("is_bicycle",),  # bicycle
    62: ("is_chair",),  # chair
    63: ("is_sofa",),  # couch
    65: ("is_bed",),  # bed
    67: ("is_table_or_desk",),  # dining table
    84: ("is_bookshelf",),  # book (COCO has no bookshelf class)
    70: ("is_toilet",),  # toilet
    81: ("is_sink",),  # sink
    72: ("is_tv",),  # tv (COCO's tv class also covers monitors)
    82: ("is_refrigerator",),  # refrigerator
}


@dataclass(frozen=True)
class DetectorRecords:
    """Flat per-detection arrays of one detector file."""

    name: str
    image_index: NDArray[np.int32]
    class_id: NDArray[np.int16]
    score: NDArray[np.float32]
    matched: NDArray[np.uint8]

    def __len__(self) -> int:
        return int(self.score.shape[0])

    def subset(self, mask: NDArray[np.bool_] | NDArray[np.intp]) -> DetectorRecords:
        """Records selected by a boolean mask or an index array."""
        return DetectorRecords(self.name, self.image_index[mask], self.class_id[mask], self.score[mask],
                               self.matched[mask])

    def for_classes(self, class_ids: tuple[int, ...] | list[int]) -> DetectorRecords:
        """Records whose COCO class is in ``class_ids``."""
        return self.subset(np.isin(self.class_id, np.asarray(class_ids, dtype=np.int16)))


def available_records() -> list[str]:
    """Names of the record files shipped with the package."""
    d = data_path("detector_confidences")
    return sorted(p.stem for p in d.glob("*.npz")) if d.exists() else []


def load_detector_records(name: str = "rfcn-resnet-101-iou-0.60", *, path: str | Path | None = None) -> DetectorRecords:
    """Load a shipped record file by name (or an explicit ``path``) with ``allow_pickle=False``."""
    p = Path(path) if path is not None else data_path("detector_confidences", f"{name}.npz")
    if not p.exists():
        raise FileNotFoundError(f"detector records {name!r} not found at {p}; available: {available_records()}")
    try:
        with np.load(p, allow_pickle=False) as d:
            arrays = {k: d[k] for k in ("image_index", "class_id", "score", "matched")}
    except KeyError as exc:
        raise FormatError(f"missing array {exc.args[0]!r}", path=p) from None
    except ValueError as exc:  # e.g. object arrays that would need pickle
        raise FormatError(f"cannot load without pickle: {exc}", path=p) from None
    n = {k: v.shape[0] for k, v in arrays.items()}
    if len(set(n.values())) != 1:
        raise FormatError(f"arrays have different lengths {n}", path=p)
    s = arrays["score"]
    if s.size and (not np.all(np.isfinite(s)) or s.min() < 0 or s.max() > 1):
        raise FormatError("field 'score': values outside [0, 1]", path=p)
    return DetectorRecords(
        name=p.stem,
        image_index=arrays["image_index"].astype(np.int32, copy=False),
        class_id=arrays["class_id"].astype(np.int16, copy=False),
        score=arrays["score"].astype(np.float32, copy=False),
        matched=arrays["matched"].astype(np.uint8, copy=False),
    )


def split_half(records: DetectorRecords, seed: int) -> tuple[DetectorRecords, DetectorRecords]:
    """Random 50/50 split by image (calibration half, evaluation half), reproducible per seed.

    Splitting by image keeps detections of one image together (they are not exchangeable).
    """
    rng = np.random.default_rng(seed)
    images = np.unique(records.image_index)
    perm = rng.permutation(images)
    cal_images = perm[: len(perm) // 2]
    in_cal = np.isin(records.image_index, cal_images)
    return records.subset(in_cal), records.subset(~in_cal)


def predicate_pool(records: DetectorRecords, predicate: str) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
    """(scores, matched) of every detection whose COCO class grounds ``predicate`` (may be empty)."""
    ids = [c for c, preds in COCO_TO_PREDICATE.items() if predicate in preds]
    sub = records.for_classes(ids)
    return sub.score, sub.matched
