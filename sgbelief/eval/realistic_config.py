"""Pydantic models of the realistic suite's configuration (``sgbelief/configs/sim/realistic.yaml``).

The suite and every parameter's source are described in docs/simulation.md ("The realistic
suite"). The file is validated once, at load time; nothing here runs per event.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from sgbelief.errors import ConfigError
from sgbelief.eval.sim_config import Camera, load_suite_yaml, load_vocabulary

__all__ = ["RealisticConfig", "RoomType", "ObjectClass", "Detection", "FalsePositives", "SegmenterRow",
           "Channels", "load_realistic_config", "PLACEMENTS", "CHANNELS"]

PLACEMENTS = ("wall", "center", "around_table", "free", "on_top")
#: the geometric channels of the suite
CHANNELS = ("mesh", "segmenter", "none")


class _M(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class RoomType(_M):
    """A ScanNet scene type: how often it occurs and how big it is."""

    probability: float = Field(gt=0, description="share of scenes of this type (normalised over types)")
    size_m: tuple[tuple[float, float], tuple[float, float]] = Field(description="ranges of the two floor sides, m")


class ObjectClass(_M):
    """One raw object category of the layouts (a row of ScanNet's label table)."""

    label: str | None = Field(description="its NYU40 label (the mesh channel's label); null: unannotated")
    coco: str | None = Field(default=None, description="the COCO class a COCO detector finds it as (null: none)")
    size: tuple[float, float, float] = Field(description="mean extent (length, depth, height), m")
    size_jitter: float = Field(default=0.2, ge=0, le=0.9, description="log-normal spread of each side")
    placement: Literal["wall", "center", "around_table", "free", "on_top"]
    z0: float = Field(default=0.0, ge=0, description="wall placement: height of the bottom edge, m")
    supports: list[str] = Field(default_factory=list, description="on_top: categories it may stand on")
    rooms: dict[str, float] = Field(description="room type -> Poisson mean count per scene")


class Detection(_M):
    """The detector records and how often a visible object is detected."""

    records: dict[str, str] = Field(description="detector key -> shipped record file (detector_records)")
    coco_ids: dict[str, int] = Field(description="COCO class name -> category id")
    instances_val2017: dict[str, int] = Field(description="COCO val2017 instances per class: recall denominator")
    score_persistence: float = Field(ge=0, lt=1, description="share of score-quantile variance fixed per object")
    record_split_seed: int = Field(description="seed of the by-image split: calibration half / stream half")


class FalsePositives(_M):
    """Where unmatched detections land."""

    shares: dict[Literal["localisation", "similar", "background"], float]
    similar: dict[str, list[str]] = Field(description="COCO class -> raw categories it is confused with")
    attraction_shape: float = Field(gt=0, description="Gamma shape of the per-object attraction multiplier")


class SegmenterRow(_M):
    accuracy: float = Field(ge=0, le=1, description="P(true NYU40 label | the segmenter labels the object)")
    confusions: dict[str, float] = Field(default_factory=dict, description="wrong-label weights (normalised)")


class Channels(_M):
    coverage: float = Field(gt=0, le=1, description="P(the channel reports a label for a claim's object)")
    persistent_error: float = Field(ge=0, le=1, description="segmenter: P(object persistently mislabelled)")
    persistent_strength: float = Field(ge=0, le=1, description="segmenter: P(the persistent label | persistent)")
    segmenter_default: SegmenterRow
    segmenter: dict[str, SegmenterRow] = Field(default_factory=dict, description="true label (or 'unlabelled')")

    def row(self, label: str) -> SegmenterRow:
        return self.segmenter.get(label, self.segmenter_default)


class RealisticConfig(_M):
    """The realistic suite: ScanNet-like layouts x real COCO detector records x channels."""

    format: Literal["sgbelief.realistic_config"] = "sgbelief.realistic_config"
    version: Literal[1] = 1
    name: str = "realistic"
    vocabulary: str
    evaluated_predicates: list[str] = Field(min_length=1)
    scenes: int = Field(ge=1, description="rooms per seed")
    frames_per_scene: tuple[int, int] = Field(description="key frames per room (range)")
    time_gap: int = Field(ge=0)
    scale: float = Field(default=1.0, gt=0, description="multiplies the number of rooms")
    transforms: dict[str, float] = Field(description="name -> exponent p of the confidence map c -> c**p")
    camera: Camera
    occlusion_ioa: float = Field(ge=0, le=1, description="an object is hidden if a nearer box covers this share")
    camera_radius: float = Field(gt=0, lt=0.5, description="trajectory radius as a share of the room sides")
    room_types: dict[str, RoomType]
    objects: dict[str, ObjectClass]
    detection: Detection
    false_positives: FalsePositives
    channels: Channels

    @model_validator(mode="after")
    def _consistency(self) -> RealisticConfig:
        for name, spec in self.objects.items():
            for room in spec.rooms:
                if room not in self.room_types:
                    raise ValueError(f"objects.{name}.rooms: unknown room type {room!r}")
            for sup in spec.supports:
                if sup not in self.objects:
                    raise ValueError(f"objects.{name}.supports: unknown category {sup!r}")
            if spec.coco is not None and spec.coco not in self.detection.coco_ids:
                raise ValueError(f"objects.{name}.coco: {spec.coco!r} is not in detection.coco_ids")
        for coco in self.detection.coco_ids:
            if coco not in self.detection.instances_val2017:
                raise ValueError(f"detection.instances_val2017: missing {coco!r}")
        for coco, cats in self.false_positives.similar.items():
            if coco not in self.detection.coco_ids:
                raise ValueError(f"false_positives.similar: {coco!r} is not in detection.coco_ids")
            for cat in cats:
                if cat not in self.objects:
                    raise ValueError(f"false_positives.similar.{coco}: unknown category {cat!r}")
        if abs(sum(self.false_positives.shares.values()) - 1.0) > 1e-6:
            raise ValueError("false_positives.shares must sum to 1")
        lo, hi = self.frames_per_scene
        if not 1 <= lo <= hi:
            raise ValueError("frames_per_scene must be a range 1 <= lo <= hi")
        return self

    def expected_label_shares(self) -> dict[str | None, float]:
        """NYU40 label (None: unannotated) -> expected share of a seed's objects (the mixture of the
        room types' Poisson means)."""
        p = {k: v.probability / sum(r.probability for r in self.room_types.values())
             for k, v in self.room_types.items()}
        mass: dict[str | None, float] = {}
        for spec in self.objects.values():
            mass[spec.label] = mass.get(spec.label, 0.0) + sum(p[r] * m for r, m in spec.rooms.items())
        total = sum(mass.values())
        return {k: v / total for k, v in sorted(mass.items(), key=lambda kv: -kv[1])}

    def labels(self) -> set[str]:
        """Every NYU40 label a layout object or a segmenter output can carry."""
        out = {s.label for s in self.objects.values() if s.label is not None}
        for row in [self.channels.segmenter_default, *self.channels.segmenter.values()]:
            out |= set(row.confusions)
        return out


def _check_vocabulary(cfg: RealisticConfig, path: Path) -> None:
    vocab = load_vocabulary(cfg.vocabulary)
    labels = set(vocab.get("labels", []))
    preds = set(vocab.get("predicates", {}))
    for p in cfg.evaluated_predicates:
        if p not in preds:
            raise ConfigError(f"{path}: key 'evaluated_predicates': {p!r} is not a predicate of {cfg.vocabulary!r}")
    for lab in sorted(cfg.labels()):
        if lab not in labels:
            raise ConfigError(f"{path}: label {lab!r} is not a label of vocabulary {cfg.vocabulary!r}")
    for key in cfg.channels.segmenter:
        if key != "unlabelled" and key not in labels:
            raise ConfigError(f"{path}: key 'channels.segmenter.{key}': not a label of {cfg.vocabulary!r}")


def load_realistic_config(name_or_path: str | os.PathLike[str] = "realistic", **overrides: Any) -> RealisticConfig:
    """Load ``sgbelief/configs/sim/<name>.yaml`` (or a path); ``overrides`` replace top-level keys.

    Errors raise :class:`ConfigError` naming the file and the key.
    """
    cfg, p = load_suite_yaml(name_or_path, RealisticConfig, "realistic suite", overrides)
    _check_vocabulary(cfg, p)
    return cfg
