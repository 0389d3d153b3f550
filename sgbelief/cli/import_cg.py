"""``sgbelief import-cg RESULT.pkl.gz``: replay a saved ConceptGraphs map through a fusion operator."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from sgbelief.cli import _console as console

if TYPE_CHECKING:
    from sgbelief.calibration.scores import ScoreCalibration


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("result", help="ConceptGraphs map (pcd_saves/full_pcd_*.pkl.gz or pcd_*.pkl.gz)")
    parser.add_argument("--operator", default="comod", help="fusion operator (default: comod)")
    parser.add_argument("--vocab", default=None,
                        help="vocabulary: a sgbelief/configs/conceptgraphs YAML or shipped name (scannet: the closed "
                             "ScanNet table; scannet200, coco80, replica) (default: the map's own class list, each "
                             "class its own predicate, synonyms merged)")
    parser.add_argument("--merge", default=None, metavar="PRED[,PRED]|all",
                        help="with the default vocabulary: also merge these taxonomy groups (is_table_or_desk), "
                             "or 'all'")
    parser.add_argument("--context", default="conceptgraphs", help="context tag kappa of the events (default: %(default)s)")
    parser.add_argument("--operator-config", default=None, help="operator config YAML (default: sgbelief/configs/operators/default.yaml)")
    parser.add_argument("--out", default="results/import-cg", help="output directory for graph.json (or graph.npz) and labels.json (default: %(default)s)")
    parser.add_argument("--channel", default=None, metavar="SCENE_DIR",
                        help="geometric channel: ScanNet mesh labels (NYU40) of this ScanNet scene folder, "
                             "read at each object's points (default: no channel)")
    parser.add_argument("--first-pose", default=None,
                        help="with --channel: the pose file of the map's frame 0 (default SCENE_DIR/pose/0.txt "
                             "if present; 'none': the map is in the mesh frame)")
    parser.add_argument("--confidence-map", default=None, metavar="JSON",
                        help="the detector's scores mapped to probabilities: a ScoreCalibration saved with "
                             "to_dict() (sgbelief.calibration.scores; for a detector whose scores are not "
                             "probabilities) (default: the scores as they are)")
    parser.add_argument("--graph-format", choices=["json", "npz"], default="json",
                        help="save the graph as graph.json (default) or graph.npz (binary layout for large maps)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.adapters.conceptgraphs.backend import ConceptGraphsBackend
    from sgbelief.adapters.conceptgraphs.importer import import_file
    from sgbelief.graph.persistence import atomic_write_text

    channel = None
    if args.channel is not None:
        from sgbelief.adapters.conceptgraphs.channels import scannet_mesh_channel

        first = False if (args.first_pose or "").lower() == "none" else args.first_pose
        channel = scannet_mesh_channel(args.channel, first_pose=first)
    confidence_map = None
    if args.confidence_map is not None:
        confidence_map = _read_confidence_map(Path(args.confidence_map))
    merge: bool | list[str] = False
    if args.merge:
        merge = True if args.merge.strip().lower() == "all" else [m.strip() for m in args.merge.split(",") if m.strip()]
    backend = ConceptGraphsBackend(args.operator, vocabulary=args.vocab, context=args.context,
                                   operator_config=args.operator_config, channel=channel, merge=merge,
                                   confidence_map=confidence_map, print_summary=False)
    with console.progress(desc="import-cg", unit="det") as bar:
        def advance(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        summary = import_file(args.result, backend, progress=advance)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    graph_path = backend.graph.save(out / f"graph.{args.graph_format}")
    atomic_write_text(out / "labels.json", json.dumps(summary.labels, indent=2, default=str))
    report = backend.summary()
    atomic_write_text(out / "summary.json", json.dumps(report.to_dict(), indent=1))
    changed = sum(1 for v in summary.labels.values() if v["belief"] != v["majority"])
    print(f"imported {summary.n_objects} objects, {summary.n_detections} detections, "
          f"{summary.n_events} evidence events ({args.operator})")
    print(f"labels differing from ConceptGraphs' majority vote: {changed}/{summary.n_objects}")
    print(f"objects left unknown (nothing commits): {summary.n_unknown}/{summary.n_objects}")
    print(report.format())
    print(f"wrote {graph_path}, {out / 'labels.json'} and {out / 'summary.json'}")
    return 0


def _read_confidence_map(path: Path) -> ScoreCalibration:
    """A ScoreCalibration from its JSON file; a file that is not one raises ConfigError naming it."""
    from pydantic import ValidationError

    from sgbelief.calibration.scores import ScoreCalibration
    from sgbelief.errors import ConfigError

    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"--confidence-map {path}: cannot read a JSON score calibration: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"--confidence-map {path}: expected a JSON object (ScoreCalibration.to_dict()), "
                          f"got {type(data).__name__}")
    try:
        return ScoreCalibration.from_dict(data)
    except ValidationError as exc:
        fields = "; ".join((f"field {'.'.join(str(x) for x in e['loc'])}: " if e["loc"] else "")
                           + e["msg"].removeprefix("Value error, ") for e in exc.errors())
        raise ConfigError(f"--confidence-map {path}: {fields}") from exc
    except ValueError as exc:
        raise ConfigError(f"--confidence-map {path}: {exc}") from exc
