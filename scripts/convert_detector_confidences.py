#!/usr/bin/env python
"""Convert the netcal detector-confidence records (pickled object arrays) into flat, pickle-free npz.

Usage:
    python scripts/convert_detector_confidences.py [SRC_DIR] [DST_DIR] [NAME ...]

Defaults: SRC_DIR = ../shared/data/detector-confidences (relative to the repo root),
DST_DIR = sgbelief/data/detector_confidences, NAMES = rfcn-resnet-101-iou-0.60 ssd-resnet-50-v1-iou-0.60.
The sources come from a known origin (see their README), which is the only reason they are opened
with allow_pickle=True here; the converted files are loaded with allow_pickle=False.
Output arrays (one entry per detection): image_index int32, class_id int16, score float32, matched uint8.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SRC = ROOT.parent / "shared" / "data" / "detector-confidences"
DEFAULT_DST = ROOT / "sgbelief" / "data" / "detector_confidences"
DEFAULT_NAMES = ["rfcn-resnet-101-iou-0.60", "ssd-resnet-50-v1-iou-0.60"]


def convert(src: Path, dst: Path) -> dict[str, int]:
    """Flatten one source file into ``dst``; return summary counts."""
    with np.load(src, allow_pickle=True) as d:  # trusted, documented source
        classes = list(d["classes"])
        scores = list(d["scores"])
        matched = list(d["matched"])
    n_img = len(classes)
    sizes = np.array([len(c) for c in classes], dtype=np.int64)
    image_index = np.repeat(np.arange(n_img, dtype=np.int32), sizes)
    class_id = np.concatenate([np.asarray(c) for c in classes]).astype(np.int16)
    score = np.concatenate([np.asarray(s) for s in scores]).astype(np.float32)
    match = np.concatenate([np.asarray(m) for m in matched]).astype(np.uint8)
    if not (len(class_id) == len(score) == len(match)):
        raise ValueError(f"{src}: ragged arrays")
    if score.min() < 0 or score.max() > 1 or not set(np.unique(match).tolist()) <= {0, 1}:
        raise ValueError(f"{src}: scores outside [0, 1] or matched not binary")
    dst.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(dst, image_index=image_index, class_id=class_id, score=score, matched=match)
    return {"images": n_img, "detections": int(len(score)), "matched": int(match.sum())}


def main(argv: list[str]) -> int:
    src_dir = Path(argv[0]) if len(argv) > 0 else DEFAULT_SRC
    dst_dir = Path(argv[1]) if len(argv) > 1 else DEFAULT_DST
    names = argv[2:] or DEFAULT_NAMES
    for name in names:
        info = convert(src_dir / f"{name}.npz", dst_dir / f"{name}.npz")
        print(f"{name}: {info}")
    lic = src_dir / "LICENSE-netcal.txt"
    if lic.exists():
        shutil.copyfile(lic, dst_dir / "LICENSE-netcal.txt")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
