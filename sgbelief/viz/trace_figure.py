"""The belief-trace figure (the paper's Figure 1(a) for any element) and the band it is drawn with.

:func:`draw_belief_band` is the one way a posterior mean with its interval is drawn: the
benchmark's Figure 1(a) (:mod:`sgbelief.eval.benchmark`) and ``sgbelief show --node`` both call it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sgbelief.graph.scene_graph import SceneGraphModel
from sgbelief.viz.style import STATUS_COLOURS, STATUS_MEANINGS, VERDICT_MARKERS, display_name
from sgbelief.viz.trace import BeliefTrace, belief_trace

#: gid of the scatter collections holding one marker per trace event (tests count their offsets)
EVENT_MARKERS_GID = "trace-events"
#: at most this many predicate panels when none is chosen (the most eventful first)
MAX_PANELS = 6
_VERDICT_LEGEND = {"⊥": "⊥ refused: geometry contradicts the claim", "?": "⊤ or ∅ (the saved log does not say which)",
                   "⊤": "⊤ geometry corroborates", "∅": "∅ geometry makes no claim",
                   "exclusion": "exclusion: a claim of a rival class, against this one"}


def draw_belief_band(ax: Any, x: Sequence[float], mean: Sequence[float], lower: Sequence[float],
                     upper: Sequence[float], *, colour: str, name: str, level: float = 0.9, step: bool = False) -> None:
    """The posterior mean as a line and its ``level`` interval as a band, labelled ``name``.
    ``step``: a step function (the belief holds between events), else straight segments."""
    where = {"drawstyle": "steps-post"} if step else {}
    ax.plot(x, mean, color=colour, label=f"{name}: mean", **where)
    ax.fill_between(x, lower, upper, color=colour, alpha=0.2, label=f"{name}: {level:.0%} interval",
                    **({"step": "post"} if step else {}))


def draw_trace(ax: Any, trace: BeliefTrace, *, tau: float = 0.5, colour: str = "#3f7fbf",
               until: int | None = None) -> None:
    """One pair's trace: the band (held until ``until``), tau, and one marker per event (colour:
    what happened; shape: verdict)."""
    ts, ms, ls, us = trace.steps(until)
    draw_belief_band(ax, ts, ms, ls, us, colour=colour, name="posterior", level=trace.level, step=True)
    ax.axhline(tau, color="0.45", ls=":", lw=1, label=f"τ = {tau:g} (committed when P > τ)")
    groups: dict[tuple[str, str], list[tuple[int, float]]] = {}
    for e in trace.events:
        groups.setdefault((e.status, e.verdict), []).append((e.t, e.mean))
    for (status, verdict), pts in sorted(groups.items()):
        marker = "D" if status == "compacted" else VERDICT_MARKERS.get(verdict, "o")
        label = f"{STATUS_MEANINGS.get(status, status)} ({len(pts)})"
        if status == "compacted":
            folded = sum(e.folded for e in trace.events if e.status == "compacted")
            label = f"compacted: {len(pts)} bucket{'s' if len(pts) > 1 else ''} folding {folded} entries"
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=26, marker=marker, zorder=3,
                   color=STATUS_COLOURS.get(status, "#555555"), edgecolors="white", linewidths=0.4,
                   label=label, gid=EVENT_MARKERS_GID)
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel(f"P({display_name(trace.predicate)})")


def _panel_title(trace: BeliefTrace, tau: float) -> str:
    a, b = trace.final
    mean = a / (a + b)
    counts = trace.counts()
    what = ", ".join(f"{n} {s}" for s, n in sorted(counts.items(), key=lambda kv: -kv[1]))
    verdict = "committed" if mean > tau else "not committed"
    n = len(trace.events)
    return (f"{trace.predicate}: {n} event{'s' if n != 1 else ''} ({what}); now Beta({a:.2f}, {b:.2f}), "
            f"mean {mean:.3f}: {verdict}")


def trace_figure(graph: SceneGraphModel, node: Any, predicates: Sequence[str] | None = None, *, tau: float = 0.5,
                 title: str | None = None) -> Any:
    """A figure with one panel per predicate of ``node`` (``predicates``, else those with evidence,
    the most eventful first, at most :data:`MAX_PANELS`). Returns the matplotlib Figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    if predicates is None:
        traces = [belief_trace(graph, node, p) for p in graph.beliefs(node)]
        traces = sorted((tr for tr in traces if tr.events), key=lambda tr: (-len(tr.events), tr.predicate))
        left_out = traces[MAX_PANELS:]
        traces = traces[:MAX_PANELS]
    else:
        traces = [belief_trace(graph, node, p) for p in predicates]
        left_out = []
    fig, axes = plt.subplots(len(traces), 1, figsize=(11, 1.2 + 2.6 * len(traces)), squeeze=False, sharex=True)
    # every panel runs to the node's last event (a belief holds between events; after the last one,
    # until the map's clock, nothing changes)
    until = max((tr.events[-1].t for tr in traces if tr.events), default=0)
    for ax, tr in zip(axes[:, 0], traces):
        draw_trace(ax, tr, tau=tau, until=until)
        ax.set_title(_panel_title(tr, tau), fontsize=9, loc="left")
        handles, labels = ax.get_legend_handles_labels()
        verdicts = sorted({e.verdict for e in tr.events if e.status != "compacted"})
        for v in verdicts:  # the marker shapes, apart from their status colours
            handles.append(Line2D([], [], ls="", marker=VERDICT_MARKERS.get(v, "o"), color="0.3"))
            labels.append(f"shape {_VERDICT_LEGEND.get(v, v)}")
        ax.legend(handles, labels, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  title="markers: one per event", title_fontsize=7)
        ax.grid(alpha=0.25)
    from matplotlib.ticker import MaxNLocator

    axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[-1, 0].set_xlabel("time step t")
    if any(e.verdict == "⊥" and (e.d_alpha or e.d_beta) for tr in traces for e in tr.events):
        fig.text(0.01, 0.0, "The belief moves at some refused events: the refused claim is not counted, but the geometric "
                 "channel's own observation of the element at that event (its verification increment) is.",
                 fontsize=7.5, ha="left", va="bottom", color="0.3")
    head = title or f"belief trace of {node}"
    if left_out:
        head += f"  ({len(left_out)} less eventful predicates not shown: {', '.join(t.predicate for t in left_out)})"
    fig.suptitle(head, fontsize=10, x=0.01, ha="left")
    fig.tight_layout()
    return fig
