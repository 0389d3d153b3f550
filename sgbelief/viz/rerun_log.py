"""A belief map in a rerun recording (the optional extra ``sgbelief[rerun]``).

Entities, under a prefix (default ``sgbelief``):

- ``<prefix>/map/objects/<node>``: the object's 3D box (or a point when only its centroid is
  known), labelled with its committed predicate and probability (``car 0.93``; ``? 0.42`` when
  nothing is above tau), coloured as in ``sgbelief show``;
- ``<prefix>/map/refused/<node>``: a red point where claims about the object were refused,
  labelled with how many;
- ``<prefix>/beliefs/<node>/<predicate>``: the posterior mean over time (rerun ``Scalars``);
- ``<prefix>/events``: a text log of refused claims and queue resolutions.

A node id with ``/`` (``d04/0056``, ``scene0000_00/3``) becomes a path of several parts, so the
viewer groups objects by scene. Times go on one sequence timeline (``t`` by default).
:func:`log_frame` logs the whole map as it stands after one frame, into the caller's current
recording (ConceptGraphs' per-frame loop); :class:`MapLogger` logs only what changed, for a replay.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sgbelief.errors import SgbeliefError
from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.viz.map_state import ObjectView, object_view
from sgbelief.viz.style import (
    EGO_COLOUR, REFUSED_COLOUR, REFUSED_STATUSES, UNCOMMITTED_COLOUR, display_name, format_probability, hex_to_rgb, label_colours,
)

EXTRA = "rerun"
#: radius of the point drawn for an object known only by its centroid, and of a refused-claim marker (m)
POINT_RADIUS = 0.15


class RerunMissingError(SgbeliefError, ImportError):
    """rerun-sdk is not installed."""


def require_rerun() -> Any:
    """The ``rerun`` module, or :class:`RerunMissingError` naming the extra that provides it."""
    try:
        import rerun
    except ImportError as exc:
        raise RerunMissingError(
            f"rerun recordings need the rerun-sdk package: pip install 'sgbelief[{EXTRA}]' ({exc})") from None
    return rerun


def entity_path(rr: Any, *parts: Any) -> str:
    """``parts`` joined into an entity path; a node id's ``/`` separates parts, each part escaped."""
    out: list[str] = []
    for part in parts:
        out += [rr.escape_entity_path_part(p) for p in str(part).split("/") if p]
    return "/".join(out)


def _box_label(view: ObjectView, tau: float) -> str:
    p = format_probability(view.probability, tau)
    return f"{display_name(view.label)} {p}" if view.label else (f"? {p}" if view.has_evidence else "no evidence")


class MapLogger:
    """Logs one map into a rerun recording (``recording``: a ``rerun.RecordingStream``, or None for
    the current one). The logger remembers what it logged, so a replay can call :meth:`log_nodes`
    with the nodes an event touched."""

    def __init__(self, recording: Any = None, *, prefix: str = "sgbelief", tau: float = 0.5, timeline: str = "t",
                 predicates: Iterable[str] = ()) -> None:
        self.rr = require_rerun()
        self.recording = recording
        self.prefix = prefix
        self.tau = float(tau)
        self.timeline = timeline
        self.colours = label_colours(predicates)
        self._series: set[tuple[Any, str]] = set()  # belief series whose style is logged
        self._refused: dict[Any, int] = {}  # node -> refused claims logged so far
        self._boxes: dict[Any, tuple[Any, ...]] = {}  # node -> what its box showed last
        self.logged = 0  #: log calls made (entities x times)

    # ------------------------------------------------------------------ plumbing
    def _log(self, path: str, archetype: Any, *, static: bool = False) -> None:
        self.rr.log(path, archetype, static=static, recording=self.recording)
        self.logged += 1

    def set_time(self, t: int) -> None:
        self.rr.set_time(self.timeline, sequence=int(t), recording=self.recording)

    def _colour(self, predicate: str | None) -> tuple[int, int, int]:
        if predicate is None:
            return hex_to_rgb(UNCOMMITTED_COLOUR)
        if predicate not in self.colours:
            self.colours = label_colours(set(self.colours) | {predicate})
        return hex_to_rgb(self.colours[predicate])

    def path(self, *parts: Any) -> str:
        return entity_path(self.rr, self.prefix, *parts)

    # ------------------------------------------------------------------ content
    def log_setup(self) -> None:
        """Static scene set-up: z up, metres."""
        self._log(self.path(), self.rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

    def log_object(self, view: ObjectView, t: int | None = None) -> bool:
        """The object's box (or point), if it has geometry and its label, P or place changed."""
        rr = self.rr
        pos = view.position_at(t) if t is not None else view.position
        if pos is None:
            return False
        label = _box_label(view, self.tau)
        shown = (label, view.label, pos)
        if self._boxes.get(view.node) == shown:
            return False
        self._boxes[view.node] = shown
        colour = self._colour(view.label)
        path = self.path("map", "objects", view.node)
        if view.box is not None:
            (x0, y0, z0), (x1, y1, z1) = view.box
            half = (0.5 * (x1 - x0), 0.5 * (y1 - y0), 0.5 * (z1 - z0))
            self._log(path, rr.Boxes3D(centers=[pos], half_sizes=[half], labels=[label], colors=[colour]))
        else:
            self._log(path, rr.Points3D([pos], radii=[POINT_RADIUS], labels=[label], colors=[colour]))
        return True

    def log_belief(self, node: Any, predicate: str, mean: float) -> None:
        """One point of the pair's belief series (its name and colour logged once)."""
        rr = self.rr
        path = self.path("beliefs", node, predicate)
        if (node, predicate) not in self._series:
            self._series.add((node, predicate))
            self._log(path, rr.SeriesLines(colors=[self._colour(predicate)], names=[f"{node} {predicate}"]), static=True)
        self._log(path, rr.Scalars(float(mean)))

    def log_refusal(self, view: ObjectView | None, node: Any, predicate: str, t: int, detail: str = "") -> None:
        """A refused claim: a text event, and the object's refused-site marker with its count."""
        rr = self.rr
        n = self._refused[node] = self._refused.get(node, 0) + 1
        self._log(self.path("events"), rr.TextLog(f"⊥ refused: {node} {predicate}{detail}", level="WARN"))
        pos = view.position_at(t) if view is not None else None
        if pos is not None:
            self._log(self.path("map", "refused", node),
                      rr.Points3D([pos], radii=[POINT_RADIUS * 1.5], colors=[hex_to_rgb(REFUSED_COLOUR)],
                                  labels=[f"⊥ ×{n}"]))

    def log_ego_track(self, points: Iterable[Any]) -> None:
        """The ego trajectory as one static line (x, y, z points)."""
        self._log(self.path("map", "ego_trajectory"),
                  self.rr.LineStrips3D([list(points)], colors=[hex_to_rgb(EGO_COLOUR)]), static=True)

    def log_ego(self, position: Any) -> None:
        """The ego position at the current time."""
        self._log(self.path("map", "ego"), self.rr.Points3D([position], radii=[0.4], colors=[hex_to_rgb(EGO_COLOUR)]))

    def log_text(self, text: str, level: str = "INFO") -> None:
        self._log(self.path("events"), self.rr.TextLog(text, level=level))

    def log_nodes(self, graph: SceneGraphModel, nodes: Iterable[Any], t: int,
                  pairs: Iterable[tuple[Any, str]] | None = None) -> None:
        """At time ``t``: the boxes of ``nodes`` (when changed) and the beliefs of ``pairs`` (default:
        every predicate of those nodes)."""
        self.set_time(t)
        prov = graph.provenance
        chosen = list(dict.fromkeys(nodes))
        for node in chosen:
            self.log_object(object_view(graph, node, self.tau), t)
        todo = pairs if pairs is not None else [(n, p) for n in chosen for p in prov.predicates_of(n)]
        for node, pred in todo:
            self.log_belief(node, pred, prov.mean(node, pred))


def log_frame(graph: SceneGraphModel, frame: int, *, recording: Any = None, prefix: str = "sgbelief", tau: float = 0.5,
              timeline: str = "t") -> int:
    """Log the map as it stands after ``frame`` into ``recording`` (default: the current rerun
    recording): every located object's box with its committed label and P, every belief's mean,
    and the claims refused at this frame (pending in Q⊥ with t == frame). Sets the recording's
    ``timeline`` to ``frame``. Returns the number of log calls made."""
    logger = MapLogger(recording, prefix=prefix, tau=tau, timeline=timeline,
                       predicates=sorted(graph.vocabulary) if graph.vocabulary else graph.predicates())
    logger.log_nodes(graph, graph.nodes(), frame)
    for entry in graph.provenance.disagreement:
        if entry.alive and entry.t == frame and entry.status.value in REFUSED_STATUSES:
            logger.log_refusal(object_view(graph, entry.node, tau) if entry.node in graph else None,
                               entry.node, entry.predicate, frame)
    return logger.logged
