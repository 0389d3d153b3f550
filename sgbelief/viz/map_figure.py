"""The top-down picture of a belief map (``sgbelief show``), after the paper's KITTI-360 figure.

Every located object is one patch: its box's footprint (x, y), or a dot when only its centroid
is known. The patch's colour is its committed label, its opacity the label's probability
(:func:`~sgbelief.viz.style.shade_alpha`); uncommitted objects are grey, objects no claim touched
are outlined only. Red rings mark the objects where claims were refused (ring area grows with the
number refused); the most refused carry letters A, B, ... that the caption under the map names.
A map much longer than wide (a drive) is cut into strips along its long axis.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

from sgbelief.errors import SgbeliefError
from sgbelief.viz.map_state import MapState, ObjectView, RefusedSite
from sgbelief.viz.style import (
    EGO_COLOUR, NO_EVIDENCE_COLOUR, REFUSED_COLOUR, UNCOMMITTED_COLOUR, display_name, format_probability, hex_to_rgb,
    label_colours, shade_alpha,
)

#: gid of the patch drawn for each object (tests count them)
OBJECT_GID = "map-object"
#: gid of the refused-site rings
REFUSED_GID = "refused-sites"
#: a view longer than this many times its width is cut into strips
STRIP_RATIO = 5.0
#: objects in one panel up to which each is labelled with its committed label and P
LABEL_LIMIT = 40
#: refused sites named with letters in the caption
LETTERED_SITES = 4

Region = tuple[float, float, float, float]  # xmin, xmax, ymin, ymax
EgoTrack = Sequence[tuple[float, float]]


class NoGeometryError(SgbeliefError):
    """A map (or the chosen region) has no object with a box or a centroid to draw."""


@dataclass(frozen=True)
class _Footprint:
    obj: ObjectView
    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def area(self) -> float:
        return (self.x1 - self.x0) * (self.y1 - self.y0)


def _footprint(o: ObjectView) -> _Footprint:
    if o.box is not None:
        (x0, y0, _), (x1, y1, _) = o.box
        return _Footprint(o, x0, y0, x1, y1)
    x, y, _ = o.position  # type: ignore[misc]
    return _Footprint(o, x, y, x, y)


def _overlaps(f: _Footprint, r: Region) -> bool:
    return f.x1 >= r[0] and f.x0 <= r[1] and f.y1 >= r[2] and f.y0 <= r[3]


def _extent(fps: Sequence[_Footprint], ego: Sequence[EgoTrack]) -> Region:
    xs = [v for f in fps for v in (f.x0, f.x1)] + [p[0] for tr in ego for p in tr]
    ys = [v for f in fps for v in (f.y0, f.y1)] + [p[1] for tr in ego for p in tr]
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    pad = max(0.05 * min(x1 - x0, y1 - y0), 0.05)
    return x0 - pad, x1 + pad, y0 - pad, y1 + pad


def _strips(r: Region, max_strips: int) -> list[Region]:
    """Cut a long view into at most ``max_strips`` pieces along its long axis."""
    w, h = r[1] - r[0], r[3] - r[2]
    ratio = max(w / h, h / w)
    n = 1 if ratio <= STRIP_RATIO else min(max_strips, math.ceil(ratio / STRIP_RATIO))
    if n == 1:
        return [r]
    if w >= h:
        step = w / n
        return [(r[0] + i * step, r[0] + (i + 1) * step, r[2], r[3]) for i in range(n)]
    step = h / n
    return [(r[0], r[1], r[2] + i * step, r[2] + (i + 1) * step) for i in range(n)]


def map_figure(state: MapState, *, title: str = "", region: Region | None = None,
               ego_tracks: Sequence[EgoTrack] = (), max_strips: int = 6, label_objects: bool | None = None) -> Any:
    """Draw ``state`` top-down; returns the matplotlib Figure. ``region`` (xmin, xmax, ymin, ymax in
    metres) keeps the objects that overlap it; ``ego_tracks``: (x, y) paths drawn as the ego
    trajectory; ``label_objects``: write each object's label and P (default: when a panel shows at
    most :data:`LABEL_LIMIT` objects). Raises :class:`NoGeometryError` when nothing is located."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fps = [_footprint(o) for o in state.located]
    if region is not None:
        fps = [f for f in fps if _overlaps(f, region)]
        ego_tracks = [[p for p in tr if region[0] <= p[0] <= region[1] and region[2] <= p[1] <= region[3]]
                      for tr in ego_tracks]
        ego_tracks = [tr for tr in ego_tracks if tr]
    if not fps:
        where = f" inside x {region[0]:g}..{region[1]:g}, y {region[2]:g}..{region[3]:g} m" if region else ""
        raise NoGeometryError(_no_geometry_message(state, where))
    shown = {f.obj.node for f in fps}
    full = _extent(fps, ego_tracks)
    if region is not None:  # the window, cut to what is drawn in it
        full = (max(full[0], region[0]), min(full[1], region[1]), max(full[2], region[2]), min(full[3], region[3]))
    panels = _strips(full, max_strips)
    colours = label_colours(state.predicates + tuple(o.label for o in state.objects if o.label))
    sites = [s for s in state.sites() if s.node in shown
             and full[0] <= s.position[0] <= full[1] and full[2] <= s.position[1] <= full[3]]
    letters = {s.node: chr(ord("A") + i) for i, s in enumerate(sites[:LETTERED_SITES])}

    caption = _caption(state, fps, sites, letters)
    # inches: panels 9.1 wide (at most 8 high: a tall map gets narrower panels), the legend beside them
    legend_w, axis_w = 3.8, 0.9
    aspect = max((p[3] - p[2]) / (p[1] - p[0]) for p in panels)
    panel_w = min(9.1, 8.0 / aspect)
    heights = [max(0.8, panel_w * (p[3] - p[2]) / (p[1] - p[0])) for p in panels]
    caption_h = 0.16 * (caption.count("\n") + 1) + 0.1 if caption else 0.0
    fig = plt.figure(figsize=(max(panel_w + axis_w + legend_w, 9.0), sum(heights) + 0.55 * len(panels) + 0.5 + caption_h),
                     layout="constrained")
    grid = fig.add_gridspec(len(panels) + bool(caption), 1, height_ratios=heights + ([caption_h] if caption else []))
    max_site = max((s.claims for s in sites), default=1)
    ring_scale = 1.0 if len(sites) <= 40 else 0.4  # an overview with many sites: smaller rings
    ax = None
    for i, panel in enumerate(panels):
        ax = fig.add_subplot(grid[i, 0])
        inside = [f for f in fps if _overlaps(f, panel)]
        labelled = label_objects if label_objects is not None else len(inside) <= LABEL_LIMIT
        _draw_objects(ax, inside, colours, state.tau, labelled, panel, {s.node for s in sites})
        _draw_sites(ax, [s for s in sites if panel[0] <= s.position[0] <= panel[1]
                         and panel[2] <= s.position[1] <= panel[3]], letters, max_site, ring_scale)
        for tr in ego_tracks:
            _draw_ego(ax, tr)
        ax.set_xlim(panel[0], panel[1])
        ax.set_ylim(panel[2], panel[3])
        ax.set_aspect("equal", adjustable="box")
        ax.set_ylabel("y [m]")
        ax.grid(alpha=0.2, lw=0.5)
        ax.tick_params(labelsize=8)
        if len(panels) > 1:
            ax.set_title(f"strip {i + 1}/{len(panels)}: x {panel[0]:.0f} to {panel[1]:.0f} m", fontsize=8, loc="left")
    assert ax is not None
    ax.set_xlabel("x [m]")
    _legend(fig, state, [f.obj for f in fps], colours, sites, bool(ego_tracks))
    fig.suptitle(_headline(title, state, [f.obj for f in fps], sites), fontsize=10, ha="left", x=0.01)
    if caption:
        cap = fig.add_subplot(grid[len(panels), 0])
        cap.axis("off")
        cap.text(0.0, 1.0, caption, fontsize=8, va="top", ha="left", family="monospace", transform=cap.transAxes)
    return fig


def _no_geometry_message(state: MapState, where: str) -> str:
    n = len(state.objects)
    if not n:
        return "the map has no objects"
    return (f"none of the map's {n} objects has a box or a centroid{where}, so there is nothing to draw "
            f"(node attributes 'bbox' or 'centroid', or boxes handed in)")


def _draw_objects(ax: Any, fps: Sequence[_Footprint], colours: dict[str, str], tau: float, labelled: bool,
                  panel: Region, ringed: Collection[Any] = ()) -> None:
    from matplotlib.patches import Circle, Rectangle

    dot = 0.006 * max(panel[1] - panel[0], panel[3] - panel[2])
    for f in sorted(fps, key=lambda f: -f.area):  # big footprints (roads, buildings) underneath
        o = f.obj
        if o.label is not None:
            colour = colours[o.label]
            face: Any = (*_rgb(colour), shade_alpha(o.probability, tau))
            edge, ls = colour, "-"
        elif o.has_evidence:
            face, edge, ls = (*_rgb(UNCOMMITTED_COLOUR), 0.45), UNCOMMITTED_COLOUR, "-"
        else:
            face, edge, ls = "none", NO_EVIDENCE_COLOUR, "--"
        if o.box is not None:
            patch = Rectangle((f.x0, f.y0), f.x1 - f.x0, f.y1 - f.y0, facecolor=face, edgecolor=edge, lw=0.8, ls=ls)
        else:
            patch = Circle((f.x0, f.y0), dot, facecolor=face, edgecolor=edge, lw=0.8, ls=ls)
        patch.set_gid(OBJECT_GID)
        ax.add_patch(patch)
        if o.track:
            ax.plot([p[1] for p in o.track], [p[2] for p in o.track], color=edge, lw=0.7, alpha=0.7)
        if labelled:
            p = format_probability(o.probability, tau)
            text = f"{display_name(o.label)} {p}" if o.label else (f"? {p}" if o.has_evidence else "")
            if text:
                # below a refused site's ring, not on it
                ax.annotate(text, (0.5 * (f.x0 + f.x1), 0.5 * (f.y0 + f.y1)), xytext=(0, -13 if o.node in ringed else 0),
                            textcoords="offset points", fontsize=7, ha="center", va="center",
                            color="black", bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.7})


def _rgb(colour: str) -> tuple[float, float, float]:
    r, g, b = hex_to_rgb(colour)
    return r / 255, g / 255, b / 255


def _ring_size(claims: int, most: int) -> float:
    """Marker area (points^2) of a refused site: from 60 (one claim) to 600 (the most refused)."""
    return 60.0 + 540.0 * math.sqrt((claims - 1) / (most - 1)) if most > 1 else 60.0


def _draw_sites(ax: Any, sites: Sequence[RefusedSite], letters: dict[Any, str], most: int, scale: float) -> None:
    if not sites:
        return
    ax.scatter([s.position[0] for s in sites], [s.position[1] for s in sites],
               s=[scale * _ring_size(s.claims, most) for s in sites], facecolors="none", edgecolors=REFUSED_COLOUR,
               linewidths=1.6, zorder=5, gid=REFUSED_GID)
    for s in sites:
        if s.node in letters:
            k = ord(letters[s.node]) - ord("A")  # neighbouring sites: letters on different sides
            offset = ((8, 8), (-18, 8), (8, 20), (-18, 20))[k % 4]  # above: object labels sit below rings
            ax.annotate(letters[s.node], (s.position[0], s.position[1]), xytext=offset, textcoords="offset points",
                        fontsize=10, fontweight="bold", color=REFUSED_COLOUR, zorder=6,
                        bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": REFUSED_COLOUR, "lw": 0.8})


def _draw_ego(ax: Any, track: EgoTrack) -> None:
    xs, ys = [p[0] for p in track], [p[1] for p in track]
    ax.plot(xs, ys, color=EGO_COLOUR, lw=1.2, zorder=4)
    ax.plot(xs[:1], ys[:1], ls="", marker="^", color=EGO_COLOUR, ms=8, zorder=4)
    ax.plot(xs[-1:], ys[-1:], ls="", marker="s", color=EGO_COLOUR, ms=7, zorder=4)


def _legend(fig: Any, state: MapState, shown: Sequence[ObjectView], colours: dict[str, str],
            sites: Sequence[RefusedSite], ego: bool) -> None:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    counts: dict[str, int] = {}
    for o in shown:
        if o.label is not None:
            counts[o.label] = counts.get(o.label, 0) + 1
    handles: list[Any] = []
    for pred in sorted(counts, key=lambda p: (-counts[p], p)):
        handles.append(Patch(facecolor=colours[pred], edgecolor=colours[pred], label=f"{display_name(pred)} ({counts[pred]})"))
    uncommitted = sum(1 for o in shown if o.label is None and o.has_evidence)
    untouched = sum(1 for o in shown if not o.has_evidence)
    if uncommitted:
        handles.append(Patch(facecolor=(*_rgb(UNCOMMITTED_COLOUR), 0.45), edgecolor=UNCOMMITTED_COLOUR,
                             label=f"uncommitted: no P > τ ({uncommitted});\n'? P' gives its highest P"))
    if untouched:
        handles.append(Patch(facecolor="none", edgecolor=NO_EVIDENCE_COLOUR, ls="--", label=f"no evidence ({untouched})"))
    tau = state.tau
    for p in (1.0, 0.5 * (1 + tau) if tau < 1 else 1.0):
        handles.append(Patch(facecolor=(0.2, 0.2, 0.2, shade_alpha(p, tau)), edgecolor="0.2", label=f"opacity: P = {p:.2f}"))
    if sites:
        n = sum(s.claims for s in sites)
        handles.append(Line2D([], [], ls="", marker="o", ms=9, mfc="none", mec=REFUSED_COLOUR, mew=1.6,
                              label=f"refused claims (⊥): {n} at {len(sites)} object{'s' if len(sites) > 1 else ''}\n"
                                    "(ring area grows with the count)"))
    if ego:
        handles.append(Line2D([], [], color=EGO_COLOUR, marker="^", ms=6, label="ego trajectory (▲ start, ■ end)"))
    fig.legend(handles=handles, loc="outside right upper", fontsize=8, title=f"committed label (P > τ = {tau:g})", title_fontsize=8, frameon=False)


def _headline(title: str, state: MapState, shown: Sequence[ObjectView], sites: Sequence[RefusedSite]) -> str:
    committed = sum(1 for o in shown if o.label is not None)
    refused = sum(s.claims for s in sites)
    line = (f"{len(shown)} objects drawn, {committed} committed (P > τ = {state.tau:g}); "
            + (f"{refused} refused claims (⊥) in view" if refused else "no refused claims in view"))
    if len(shown) < len(state.objects):
        line += f" (of {len(state.objects)} objects and {len(state.refused)} refused claims in all)"
    if state.folded:
        line += (f"\ncompaction folded {state.folded} older entries of these objects (up to t = {state.folded_until}) "
                 f"into buckets: refusals among them are no longer in the provenance")
    return f"{title}\n{line}" if title else line


def _caption(state: MapState, fps: Sequence[_Footprint], sites: Sequence[RefusedSite], letters: dict[Any, str]) -> str:
    lines = []
    for s in sites:
        if s.node in letters:
            preds = ", ".join(display_name(p) for p in s.predicates[:3])
            span = f"t {s.first_t}" if s.first_t == s.last_t else f"t {s.first_t} to {s.last_t}"
            lines.append(f"{letters[s.node]}: {s.node}  {s.claims} refused ({preds}; {span})")
    missing = len(state.unlocated)
    if missing:
        lines.append(f"{missing} object{'s' if missing > 1 else ''} without geometry not drawn")
    return "\n".join(lines)
