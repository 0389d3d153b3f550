"""The thresholds of the built-in geometric predicates: :class:`RelationConfig` (lengths in metres),
read from a query file's ``relations:`` section by :meth:`RelationConfig.from_mapping`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from sgbelief.errors import ConfigError

__all__ = ["RelationConfig"]


@dataclass(frozen=True)
class RelationConfig:
    """Thresholds of the built-in geometric predicates (lengths in metres).

    near_distance: ``is_near_<class>`` / ``near`` edges hold when the box-to-box distance
        (0 when the boxes touch or overlap) is <= this.
    workspace_band: ``is_workspace_height`` holds when the top surface (bbox zmax) lies this many
        metres above the floor, inclusive (desks ~0.72-0.76 m, counters ~0.9 m).
    on_tolerance: ``on``: the upper box's bottom lies within +-this of the lower box's top.
    on_min_overlap: ``on``: the fraction of the upper box's footprint (xy area) that overlaps
        the lower box's footprint must be >= this.
    access_depth: ``is_accessible``: depth of the free-floor slab checked in front of the node.
    access_z: ``is_accessible``: the slab spans these heights above the floor (ignores carpets
        and things hanging from the ceiling).
    min_overlap: an obstacle blocks the slab only if it penetrates it by more than this along
        every axis (boxes that merely touch do not block).
    facing_distance: ``is_facing_seating``: a seat counts when its box is within this distance.
    facing_half_angle_deg: ... and the horizontal direction to its centre is within this angle of
        a front direction.
    seating_class: the class name whose members are seats (see ``class_aliases``).
    structural_labels: labels that are never obstacles nor supporting / resting objects.
    stationary_max_displacement: ``is_stationary``: every track centroid lies within this
        distance of the track's median centroid (tracks need >= ``stationary_min_track``
        entries); without a track, ``speed <= stationary_max_speed`` (m/s) or ``stationary``.
    near_road_px: ``is_near_road_px``: ``road_distance_px`` (pixels) <= this.
    intersection_radius: ``is_at_intersection`` from ``intersection_distance`` (m) when the
        boolean ``at_intersection`` is absent.
    class_aliases: class name -> labels that count as that class (e.g. pedestrian -> person).
    use_committed_labels: a node also counts as class ``c`` when its belief on ``is_<c>`` is
        committed (probability > ``commit_tau``) -- the paper's "committed or ground-truth label".
    extra: free-form thresholds for user predicates.
    """

    near_distance: float = 1.0
    workspace_band: tuple[float, float] = (0.6, 1.1)
    on_tolerance: float = 0.05
    on_min_overlap: float = 0.3
    access_depth: float = 0.6
    access_z: tuple[float, float] = (0.1, 1.5)
    min_overlap: float = 0.02
    facing_distance: float = 3.0
    facing_half_angle_deg: float = 60.0
    seating_class: str = "seating"
    structural_labels: tuple[str, ...] = ("wall", "floor", "ceiling")
    stationary_max_displacement: float = 1.0
    stationary_min_track: int = 2
    stationary_max_speed: float = 0.3
    near_road_px: float = 50.0
    intersection_radius: float = 15.0
    class_aliases: Mapping[str, tuple[str, ...]] = field(
        default_factory=lambda: {
            "pedestrian": ("person", "pedestrian"),
            "car": ("car",),
            "seating": ("chair", "sofa", "couch", "bench", "stool", "armchair", "seat"),
            "table_or_desk": ("table", "desk"),
        }
    )
    use_committed_labels: bool = True
    commit_tau: float = 0.5
    extra: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any] | None, *, base: RelationConfig | None = None) -> RelationConfig:
        """Build from a plain mapping (e.g. a YAML ``relations:`` section); unknown keys raise."""
        base = base or cls()
        if not data:
            return base
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ConfigError(f"relations: unknown key(s) {unknown}; known: {sorted(names)}")
        kw: dict[str, Any] = {}
        for key, value in data.items():
            if key in ("workspace_band", "access_z"):
                if not (isinstance(value, (list, tuple)) and len(value) == 2):
                    raise ConfigError(f"relations.{key}: expected [low, high], got {value!r}")
                value = (float(value[0]), float(value[1]))
            elif key == "structural_labels":
                value = tuple(str(v) for v in value)
            elif key == "class_aliases":
                merged = dict(base.class_aliases)
                merged.update({str(k): tuple(str(x) for x in v) for k, v in dict(value).items()})
                value = merged
            elif key == "extra":
                value = {**base.extra, **dict(value)}
            elif key in ("use_committed_labels",):
                value = bool(value)
            elif key in ("seating_class",):
                value = str(value)
            elif key == "stationary_min_track":
                value = int(value)
            else:
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise ConfigError(f"relations.{key}: expected a number, got {value!r}") from None
            kw[key] = value
        return replace(base, **kw)

    def labels_of(self, cls_name: str) -> frozenset[str]:
        """Labels counting as class ``cls_name`` (itself plus its aliases)."""
        return frozenset((cls_name, *self.class_aliases.get(cls_name, ())))
