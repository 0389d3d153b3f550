"""``sgbelief show MAP_DIR --out map.png``: a top-down picture of a saved map, or one element's belief trace."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("map_dir", type=Path,
                   help="saved graph: a directory holding graph.json or graph.npz, or the .json / .npz file")
    p.add_argument("--out", type=Path, default=None,
                   help="PNG to write (default: map.png, or trace.png with --node)")
    p.add_argument("--node", default=None,
                   help="draw this node's belief trace over time (posterior mean, 90%% interval, one marker per "
                        "event) instead of the map (default: draw the map)")
    p.add_argument("--predicate", default=None,
                   help="with --node: comma-separated predicates to trace (default: those with evidence, the most "
                        "eventful first, at most 6)")
    p.add_argument("--tau", type=float, default=0.5,
                   help="commit threshold: an object's label is a predicate with P > tau (default: %(default)s)")
    p.add_argument("--region", type=float, nargs=4, metavar=("XMIN", "XMAX", "YMIN", "YMAX"), default=None,
                   help="draw only this window, in metres (default: the whole map)")
    p.add_argument("--around", default=None, metavar="NODE",
                   help="draw the window of --radius metres around this node (default: the whole map)")
    p.add_argument("--radius", type=float, default=30.0, help="half-width of the --around window in metres (default: %(default)s)")
    p.add_argument("--scene", default=None,
                   help="draw only this scene's nodes (node attribute 'scene', else the id's part before '/'); "
                        "default: the map's only scene, or its first one with a note when it holds several")
    p.add_argument("--nodes", type=Path, default=None,
                   help="nodes.json (simulator, bench): geometry for nodes the map lacks it for, and the ego "
                        "trajectory (default: the map's own node attributes only)")
    p.add_argument("--scannet", type=Path, default=None, metavar="SCENES",
                   help="ScanNet scene folder (or a folder of them): boxes from the ScanNet loader for nodes "
                        "<sceneId>/<objectId> (needs open3d; default: the map's own node attributes only)")
    p.add_argument("--title", default=None, help="title (default: the map's path and operator)")
    p.add_argument("--max-strips", type=int, default=6,
                   help="a map much longer than wide is cut into at most this many strips (default: %(default)s)")
    p.add_argument("--dpi", type=int, default=110, help="resolution of the PNG (default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.graph.persistence import atomic_write_binary, load_graph

    graph = load_graph(args.map_dir)
    title = args.title if args.title is not None else _title(args.map_dir, graph)
    if args.node is not None:
        fig = _trace(args, graph, title)
        out = args.out or Path("trace.png")
    else:
        fig = _map(args, graph, title)
        out = args.out or Path("map.png")
    import matplotlib.pyplot as plt

    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        atomic_write_binary(out, lambda f: fig.savefig(f, format="png", dpi=args.dpi, bbox_inches="tight"))
    finally:
        plt.close(fig)
    print(f"wrote {out}")
    return 0


def _node_id(graph: Any, text: str) -> Any:
    """The node ``text`` names (an integer id when the map has no such string id)."""
    from sgbelief.errors import UnknownNodeError

    if text in graph:
        return text
    if text.lstrip("-").isdigit() and int(text) in graph:
        return int(text)
    raise UnknownNodeError(text)


def _title(map_dir: Path, graph: Any) -> str:
    from sgbelief.fusion.registry import OPERATOR_NAMES

    where = map_dir.parent if map_dir.suffix in (".json", ".npz") else map_dir
    operator = graph.meta.get("operator") or (where.name if where.name in OPERATOR_NAMES else None)
    return f"map {map_dir}" + (f" · operator {operator}" if operator else "")


def _trace(args: argparse.Namespace, graph: Any, title: str) -> Any:
    from sgbelief.errors import SgbeliefError
    from sgbelief.viz.trace_figure import trace_figure

    node = _node_id(graph, args.node)
    preds = [p.strip() for p in args.predicate.split(",") if p.strip()] if args.predicate else None
    if preds is None and not graph.beliefs(node):
        raise SgbeliefError(f"node {node!r} has no beliefs: no claim touched it, so it has no trace to draw")
    if preds is not None:
        for p in preds:
            graph.check_predicate(p)
    return trace_figure(graph, node, preds, tau=args.tau, title=f"{title} · belief trace of node {node}")


def _map(args: argparse.Namespace, graph: Any, title: str) -> Any:
    from sgbelief.viz.map_figure import NoGeometryError, map_figure
    from sgbelief.viz.map_state import map_state, scene_of

    wanted = args.scene
    if wanted is None and args.around is not None:  # the window lies in the frame of the node it is around
        wanted = scene_of(graph, _node_id(graph, args.around))
    chosen, scene = _scene_nodes(graph, wanted)
    if scene is not None and args.title is None:
        title += f" · scene {scene}"
    boxes: dict[Any, Any] = {}
    ego: list[list[tuple[float, float]]] = []
    if args.nodes is not None:
        boxes, ego = _from_nodes_file(args.nodes, graph, chosen)
    if args.scannet is not None:
        boxes.update(_scannet_boxes(args.scannet))
    state = map_state(graph, args.tau, boxes={n: b for n, b in boxes.items() if n in graph}, nodes=chosen)
    region = tuple(args.region) if args.region is not None else None
    if args.around is not None:
        node = _node_id(graph, args.around)
        pos = next((o.position for o in state.objects if o.node == node), None)
        if pos is None:
            from sgbelief.errors import SgbeliefError

            raise SgbeliefError(f"--around {args.around}: the node has no box or centroid")
        r = args.radius
        region = (pos[0] - r, pos[0] + r, pos[1] - r, pos[1] + r)
    if region is not None and (region[0] >= region[1] or region[2] >= region[3]):
        from sgbelief.errors import ConfigError

        raise ConfigError("--region: give XMIN XMAX YMIN YMAX with XMIN < XMAX and YMIN < YMAX")
    try:
        fig = map_figure(state, title=title, region=region, ego_tracks=ego, max_strips=max(1, args.max_strips))
    except NoGeometryError as exc:
        if region is not None:
            raise
        raise NoGeometryError(f"{exc}; give the geometry with --nodes NODES_JSON (simulated logs: the nodes.json the "
                              f"log came with) or --scannet SCENES (ScanNet maps)") from None
    missing = len(state.unlocated)
    if missing:
        log.warning("%d of %d objects have no box or centroid and are not drawn", missing, len(state.objects))
    return fig


def _scene_nodes(graph: Any, wanted: str | None) -> tuple[list[Any] | None, str | None]:
    """(the nodes to draw, the scene drawn): every node of a one-scene map (None, None), else those
    of ``wanted`` (default: the first scene)."""
    from sgbelief.errors import ConfigError
    from sgbelief.viz.map_state import nodes_by_scene

    by_scene = nodes_by_scene(graph)
    names = sorted((s for s in by_scene if s is not None))
    if wanted is not None:
        if wanted not in by_scene:
            raise ConfigError(f"--scene: no node of the map belongs to scene {wanted!r}; its scenes: "
                              f"{', '.join(names[:20]) or '(none named)'}{' ...' if len(names) > 20 else ''}")
        return by_scene[wanted], wanted
    if len(by_scene) <= 1:
        return None, None
    first = names[0]
    log.warning("the map holds %d scenes (%s%s), each in its own frame; drawing %s (--scene NAME draws another)",
                len(names), ", ".join(names[:6]), ", ..." if len(names) > 6 else "", first)
    return by_scene[first] + by_scene.get(None, []), first


def _from_nodes_file(path: Path, graph: Any, chosen: list[Any] | None) -> tuple[dict[Any, Any], list[list[tuple[float, float]]]]:
    """Boxes of the nodes.json nodes whose graph node has none, and the ego track of the scenes drawn."""
    from sgbelief.eval.formats import read_nodes
    from sgbelief.viz.map_state import scene_of

    doc = read_nodes(path)
    boxes = {}
    for nid, info in doc.nodes.items():
        attrs = graph.find_node(nid)
        if attrs is not None and attrs.get("bbox") is None:
            boxes[nid] = (tuple(info.bbox_min), tuple(info.bbox_max))
    drawn = graph.nodes() if chosen is None else chosen
    scenes = {scene_of(graph, n) for n in drawn} | {doc.nodes[n].scene for n in drawn if n in doc.nodes}
    ego = [[(p[1], p[2]) for p in sc.ego_track] for name, sc in doc.scenes.items() if name in scenes and sc.ego_track]
    return boxes, ego


def _scannet_boxes(path: Path) -> dict[str, Any]:
    """node id ``<sceneId>/<objectId>`` -> the object's axis-aligned box, from the ScanNet loader."""
    from sgbelief.adapters.scannet import load_scenes

    out = {}
    for scene in load_scenes(path, on_unknown_label="skip"):
        for oid, obj in scene.objects.items():
            out[scene.node_id(oid)] = obj.bbox
    return out
