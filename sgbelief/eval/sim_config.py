"""Pydantic models of the simulator configuration (``sgbelief/configs/sim/*.yaml``); see docs/simulation.md."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from sgbelief.errors import ConfigError
from sgbelief.fusion.compatibility import VocabularyFile
from sgbelief.resources import config_dir

_M = TypeVar("_M", bound=BaseModel)

__all__ = [
    "SimConfig",
    "ClassSpec",
    "SegmenterClass",
    "LatentSpec",
    "Distortion",
    "Profile",
    "load_sim_config",
    "load_vocabulary",
    "Monolithic",
]


class _M(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class ClassSpec(_M):
    """One true class of scene element: how many, how big, where."""

    density: float = Field(ge=0, description="outdoor: elements per 100 m of road; indoor: Poisson mean per scene")
    size: tuple[float, float, float] = Field(description="mean extent (length, width, height) in metres")
    size_jitter: float = Field(default=0.15, ge=0, le=0.9, description="relative size spread")
    placement: str = Field(description="placement rule, see docs/simulation.md")
    moving_fraction: float = Field(default=0.0, ge=0, le=1)
    speed: tuple[float, float] = Field(default=(0.0, 0.0), description="speed range of movers, m/s")
    near_intersection: float = Field(default=0.0, ge=0, le=1, description="fraction placed at intersections")
    scene_types: dict[str, float] | None = Field(default=None, description="indoor: Poisson mean per scene type")


class SegmenterClass(_M):
    """Mask2Former-like per-class behaviour of the segmenter channel."""

    miss: float = Field(ge=0, le=1, description="P(no label) for a visible, unoccluded element")
    accuracy: float = Field(ge=0, le=1, description="P(true label | labelled)")
    confusions: dict[str, float] = Field(default_factory=dict, description="wrong-label distribution (normalised)")


class LatentSpec(_M):
    """Latent VLM evidence score for one predicate: logit ~ N(mu_pos | mu_neg, sigma) + element offset."""

    mu_pos: float
    mu_neg: float
    sigma: float = Field(gt=0)
    confident_wrong: float = Field(ge=0, le=1, description="P(latent drawn from the opposite outcome)")


class Distortion(_M):
    """Strictly increasing confidence mapping c = sigmoid(gain * z + bias), gain > 0."""

    gain: float = Field(gt=0)
    bias: float = 0.0


class Profile(_M):
    """A foundation-model profile: its context tag and per-predicate confidence distortion."""

    context: str = Field(min_length=1)
    description: str = ""
    default: Distortion = Distortion(gain=1.0, bias=0.0)
    classes: dict[str, Distortion] = Field(default_factory=dict)

    def distortion(self, predicate: str) -> Distortion:
        return self.classes.get(predicate, self.default)


class Camera(_M):
    focal_px: float = Field(gt=0)
    width: int = Field(gt=0)
    height: int = Field(gt=0)
    height_m: float = Field(description="camera height above ground / floor, m")
    max_range_m: float = Field(gt=0)
    min_box_px: float = Field(default=8.0, ge=0, description="min projected box side to count as visible")


class Outdoor(_M):
    road_length_m: tuple[float, float] = Field(description="per-sequence road length range, m")
    road_half_width_m: float
    sidewalk_width_m: float
    intersection_spacing_m: float = Field(gt=0)
    intersection_radius_m: float = Field(gt=0, description="is_at_intersection threshold")
    cruise_speed_mps: tuple[float, float]
    step_s: float = Field(gt=0, description="time between frames (2 Hz -> 0.5 s)")
    stop_probability: float = Field(ge=0, le=1, description="P(ego stops at an intersection)")
    stop_steps: tuple[int, int]
    near_road_px: float = 50.0
    near_pedestrian_m: float = 5.0
    drive_direction_half_angle_deg: float = 15.0


class Indoor(_M):
    room_size_m: tuple[tuple[float, float], tuple[float, float]]
    room_height_m: float
    frames_per_scene: tuple[int, int]
    scene_types: dict[str, float] = Field(description="scene type -> probability")
    near_window_m: float = 1.0
    workspace_height_m: tuple[float, float] = (0.6, 1.1)
    access_depth_m: float = 0.6
    facing_distance_m: float = 3.0
    facing_half_angle_deg: float = 60.0


class Occlusion(_M):
    ioa_threshold: float = Field(ge=0, le=1, description="occluded if a nearer box covers this fraction")
    random_rate: float = Field(ge=0, le=1, description="P(occluded by an unmodelled occluder) per frame")


class Oracle(_M):
    unlabeled: list[str] = Field(default_factory=list, description="true labels the oracle never asserts")


class Segmenter(_M):
    default: SegmenterClass
    classes: dict[str, SegmenterClass] = Field(default_factory=dict)
    persistent_error: float = Field(ge=0, le=1, description="P(element persistently mislabelled)")
    persistent_strength: float = Field(ge=0, le=1, description="P(persistent label used | persistent)")

    def spec(self, label: str) -> SegmenterClass:
        return self.classes.get(label, self.default)


class Detector(_M):
    proposals: dict[str, dict[str, float]] = Field(description="true label -> {predicate: P(proposal)/frame}")
    occluded_factor: float = Field(ge=0, le=1)
    detectability_shape: float = Field(gt=0, description="Gamma shape of per-element proposal multiplier")
    confusability_shape: float = Field(gt=0, description="Gamma shape of per-element wrong-proposal multiplier")
    box_jitter: float = Field(ge=0, description="relative std of box centre / size error")
    hallucinations_per_frame: float = Field(ge=0)
    hallucination_predicates: dict[str, float]
    hallucination_offset: tuple[float, float] = Field(description="box shift in box widths")
    min_logged_mass: float = Field(ge=0, lt=1, description="masses below this are not logged")
    ground_overlap_factor: float = Field(
        default=1.0, ge=0, le=1,
        description="overlap of a box with a flat ground element (road / sidewalk / floor strip) other than the "
                    "box's own element, relative to its bounding-box IoU (the region's pixel mask is a thin wedge)",
    )
    candidate_filter: dict[str, list[str]] | None = Field(
        default=None, description="predicate -> candidate true classes admitted at intake (indoor)"
    )


class Vlm(_M):
    default: LatentSpec
    latent: dict[str, LatentSpec] = Field(default_factory=dict)
    element_sigma: float = Field(ge=0, description="std of the persistent per-(element, predicate) offset")
    ar_rho_per_step: float = Field(ge=0, lt=1, description="AR(1) correlation of latent noise per time step")
    profiles: dict[str, Profile]

    def spec(self, predicate: str) -> LatentSpec:
        return self.latent.get(predicate, self.default)


class Monolithic(_M):
    """The cold monolithic compound prompt ("is this a parked car near a crossing?"), asked once per
    visible element and named compound (docs/simulation.md, "Monolithic compound channel").

    The object part is read with the VLM-typed predicate's own latent model (``vlm.latent``) and
    the element's own persistent offset; each relation is read from the crop with ``relation``
    (``null``: ``vlm.default``, the model's reliability on a predicate with no spec of its own),
    or a row of ``relations``. Nothing here is fitted to a retrieval result."""

    queries: str | None = Field(default=None, description="named-query set (scannet | kitti360 | YAML); "
                                                          "null: the vocabulary's")
    relation: LatentSpec | None = Field(default=None, description="latent model of a relation read from the "
                                                                  "image; null: vlm.default")
    relations: dict[str, LatentSpec] = Field(default_factory=dict, description="per-relation overrides")

    def relation_spec(self, name: str, vlm: Vlm) -> LatentSpec:
        return self.relations.get(name) or self.relation or vlm.default


class SimConfig(_M):
    """A simulated suite (outdoor KITTI-360-like or indoor ScanNet-like)."""

    format: Literal["sgbelief.sim_config"] = "sgbelief.sim_config"
    version: Literal[1] = 1
    name: str
    kind: Literal["outdoor", "indoor"]
    vocabulary: str = Field(description="vocabulary name (sgbelief/configs/vocab/<name>.yaml) or path")
    scenes: list[str] = Field(min_length=1)
    evaluated_predicates: list[str] = Field(min_length=1)
    time_gap: int = Field(ge=0, description="empty time steps between consecutive scenes")
    camera: Camera
    outdoor: Outdoor | None = None
    indoor: Indoor | None = None
    classes: dict[str, ClassSpec]
    occlusion: Occlusion
    oracle: Oracle
    segmenter: Segmenter
    detector: Detector
    vlm: Vlm
    profile: str = Field(default="vlm_a", description="default profile")
    channel: Literal["oracle", "segmenter"] = "oracle"
    fm_source: Literal["parametric", "detector_records"] = "parametric"
    detector_records: str = "rfcn-resnet-101-iou-0.60"
    scale: float = Field(default=1.0, gt=0, description="multiplies densities (outdoor) / scene frames")
    monolithic: Monolithic = Field(default_factory=Monolithic, description="the cold monolithic compound prompt")

    @model_validator(mode="after")
    def _consistency(self) -> SimConfig:
        if self.kind == "outdoor" and self.outdoor is None:
            raise ValueError("kind 'outdoor' needs an 'outdoor' section")
        if self.kind == "indoor" and self.indoor is None:
            raise ValueError("kind 'indoor' needs an 'indoor' section")
        if self.profile not in self.vlm.profiles:
            raise ValueError(f"profile {self.profile!r} not in vlm.profiles {sorted(self.vlm.profiles)}")
        for lab in self.detector.proposals:
            if lab not in self.classes:
                raise ValueError(f"detector.proposals: {lab!r} is not a class of this suite")
        return self


def load_vocabulary(name_or_path: str) -> dict[str, Any]:
    """The raw vocabulary YAML (labels + predicates with positive/negative sets)."""
    p = Path(name_or_path)
    if not p.suffix:
        p = config_dir() / "vocab" / f"{name_or_path}.yaml"
    try:
        with open(p, encoding="utf-8") as fh:
            doc = yaml.safe_load(fh)
    except FileNotFoundError:
        raise ConfigError(f"vocabulary {name_or_path!r} not found ({p})") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not UTF-8 text (byte offset {exc.start})") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: bad YAML: {exc}") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"{p}: a vocabulary must be a YAML mapping")
    if doc.get("format", "sgbelief.vocabulary") != "sgbelief.vocabulary":
        raise ConfigError(f"{p}: key 'format': expected 'sgbelief.vocabulary', got {doc['format']!r}")
    version = doc.get("version", 1)
    if type(version) is not int or version != 1:
        raise ConfigError(f"{p}: key 'version': unsupported version {version!r} (this sgbelief reads 1)")
    if doc.get("exhaustive"):  # negative sets are derived from the labels: the validated file spells them out
        try:
            doc = VocabularyFile.model_validate(doc).model_dump()
        except ValidationError as exc:
            err = exc.errors()[0]
            where = ".".join(str(x) for x in err["loc"])
            raise ConfigError(f"{p}: key '{where}': {err['msg'].removeprefix('Value error, ')}") from None
    return doc


def _check_labels(cfg: SimConfig, vocab: dict[str, Any]) -> None:
    labels = set(vocab.get("labels", []))
    preds = set(vocab.get("predicates", {}))
    for lab in cfg.classes:
        if lab not in labels:
            raise ConfigError(f"classes.{lab}: not a label of vocabulary {cfg.vocabulary!r}")
    for where, names in [("segmenter confusions", [c for s in [cfg.segmenter.default, *cfg.segmenter.classes.values()]
                                                   for c in s.confusions]),
                         ("oracle.unlabeled", cfg.oracle.unlabeled),
                         ("segmenter.classes", list(cfg.segmenter.classes))]:
        for lab in names:
            if lab not in labels:
                raise ConfigError(f"{where}: {lab!r} is not a label of vocabulary {cfg.vocabulary!r}")
    used = set(cfg.evaluated_predicates) | set(cfg.vlm.latent) | set(cfg.detector.hallucination_predicates)
    used |= {p for row in cfg.detector.proposals.values() for p in row}
    for prof, spec in cfg.vlm.profiles.items():
        used |= {f"{p}" for p in spec.classes}
    if cfg.detector.candidate_filter:
        used |= set(cfg.detector.candidate_filter)
        for p, labs in cfg.detector.candidate_filter.items():
            for lab in labs:
                if lab not in labels:
                    raise ConfigError(f"detector.candidate_filter.{p}: {lab!r} is not a vocabulary label")
    for p in used:
        if p not in preds:
            raise ConfigError(f"predicate {p!r} is not defined by vocabulary {cfg.vocabulary!r}")


def load_suite_yaml(name_or_path: str | os.PathLike[str], model: type[_M], what: str,
                    overrides: dict[str, Any]) -> tuple[_M, Path]:
    """A suite config validated by ``model``: ``sgbelief/configs/sim/<name>.yaml`` or a path, top-level
    keys replaced by ``overrides``; errors raise :class:`ConfigError` naming the file and the key."""
    p = Path(name_or_path)
    if not p.suffix and not p.exists():
        p = config_dir() / "sim" / f"{name_or_path}.yaml"
    try:
        with open(p, encoding="utf-8") as fh:
            raw = yaml.safe_load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{what} config {str(name_or_path)!r} not found ({p})") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: bad YAML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{p}: not UTF-8 text (byte offset {exc.start})") from None
    if not isinstance(raw, dict):
        raise ConfigError(f"{p}: top level must be a mapping")
    raw.update({k: v for k, v in overrides.items() if v is not None})
    try:
        return model.model_validate(raw), p
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err["loc"]) or "(top level)"
        raise ConfigError(f"{p}: key '{loc}': {err['msg'].removeprefix('Value error, ')}") from None


def load_sim_config(name_or_path: str | os.PathLike[str], **overrides: Any) -> SimConfig:
    """Load ``sgbelief/configs/sim/<name>.yaml`` (or a path); ``overrides`` replace top-level keys.

    Errors raise :class:`ConfigError` naming the offending key.
    """
    cfg, _ = load_suite_yaml(name_or_path, SimConfig, "simulation", overrides)
    _check_labels(cfg, load_vocabulary(cfg.vocabulary))
    return cfg
