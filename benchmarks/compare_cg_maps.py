"""The maps the ConceptGraphs backend builds in the harness, in a canonical form, to compare two versions.

    SGBELIEF_CONCEPTGRAPH_PATH=/path/to/concept-graphs python benchmarks/compare_cg_maps.py dump OUT_DIR \\
        [--seed 1] [--frames 30] [--channels oracle,none] [--clutter 0]
    python benchmarks/compare_cg_maps.py diff DIR_A DIR_B

``dump`` runs ConceptGraphs' own loop (benchmarks/cg_harness.py) with the backend once per channel
and writes, per run, ``<branch>-<channel>.json``: the belief graph as sgbelief saves it (nodes with
their attributes, beliefs, provenance entries with their event ids) and the labels ConceptGraphs
reads out of the final map, with ali-dev's random uuids renamed ``uuid-0``, ``uuid-1``, ... in
order of appearance in the saved graph, so two runs of one version give the same bytes. ``diff``
compares the files two dumps share byte for byte and prints the first difference of each that
differs; exit status 1 when one does.

The check behind "maps and provenance unchanged" for changes that should not alter what the
backend computes (docs/performance.md).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

UUID = re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}")


def canonical(graph_text: str, labels: list[str]) -> str:
    """The saved graph and the labels as one JSON text, uuids renamed in order of appearance."""
    names: dict[str, str] = {}

    def rename(m: re.Match[str]) -> str:
        return names.setdefault(m.group(0), f"uuid-{len(names)}")

    graph = json.loads(UUID.sub(rename, graph_text))
    return json.dumps({"graph": graph, "labels": labels}, indent=1, sort_keys=True) + "\n"


def dump(out_dir: Path, cg_path: str, seed: int, frames: int, channels: list[str], clutter: int = 0) -> list[Path]:
    import cg_harness as H

    from sgbelief.graph.persistence import save_graph

    world = H.render_world(n_frames=frames, clutter=clutter)
    cg = H.import_conceptgraph(cg_path)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for ch in channels:
        backend = H.make_backend("comod", H.make_channel(world, ch))
        r = H.run(world, cg, cg_path, backend=backend, seed=seed)
        backend.flush()
        with tempfile.TemporaryDirectory() as tmp:
            text = Path(save_graph(backend.graph, Path(tmp) / "graph.json")).read_text()
        path = out_dir / f"{cg[3]}-{ch}.json"
        path.write_text(canonical(text, list(r.labels)))
        print(f"{path}: {len(backend.graph)} nodes, {backend.evidence_count()} evidence entries, "
              f"labels {r.labels}")
        written.append(path)
    return written


def diff(a: Path, b: Path) -> int:
    names = sorted({p.name for p in a.glob("*.json")} & {p.name for p in b.glob("*.json")})
    if not names:
        print(f"no file common to {a} and {b}")
        return 1
    status = 0
    for name in names:
        x, y = (a / name).read_text(), (b / name).read_text()
        if x == y:
            print(f"{name}: identical ({len(x)} bytes)")
            continue
        status = 1
        lx, ly = x.splitlines(), y.splitlines()
        k = next((i for i, (u, v) in enumerate(zip(lx, ly)) if u != v), min(len(lx), len(ly)))
        print(f"{name}: DIFFERS from line {k + 1}:\n  {a.name}: {lx[k] if k < len(lx) else '<end>'}\n"
              f"  {b.name}: {ly[k] if k < len(ly) else '<end>'}")
    return status


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("dump", help="run the harness and write the canonical maps")
    d.add_argument("out_dir", type=Path)
    d.add_argument("--cg", default=os.environ.get("SGBELIEF_CONCEPTGRAPH_PATH"))
    d.add_argument("--seed", type=int, default=1)
    d.add_argument("--frames", type=int, default=30)
    d.add_argument("--channels", default="oracle,none")
    d.add_argument("--clutter", type=int, default=0, help="small objects scattered in the room (more detections a frame)")
    c = sub.add_parser("diff", help="compare two dumps file by file")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "diff":
        return diff(args.a, args.b)
    if not args.cg:
        ap.error("pass --cg or set SGBELIEF_CONCEPTGRAPH_PATH")
    dump(args.out_dir, args.cg, args.seed, args.frames, [c for c in args.channels.split(",") if c], args.clutter)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
