"""``sgbelief vocab check VOCAB``: the verdict matrix of an open-vocabulary subsumption table."""

from __future__ import annotations

import argparse
import json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    check = sub.add_parser("check", help="derive the table and print what contradicts what",
                           description="Derive the subsumption table of a detector class list and print, per "
                                       "predicate, the geometric labels that corroborate it (T), contradict it "
                                       "(⊥) or decide nothing (∅).")
    check.add_argument("vocab", help="class list (.txt one name a line, .yaml/.json list), a shipped list "
                                     "(scannet200, coco80, nyu40), a sgbelief/configs/conceptgraphs vocabulary YAML, "
                                     "or a sgbelief/configs/vocab subsumption table")
    check.add_argument("--taxonomy", default="indoor", help="taxonomy YAML or shipped name (default: indoor)")
    check.add_argument("--mapping", default=None,
                       help="label mapping YAML or shipped name (scannet200_nyu40, coco80_nyu40): the channel's labels")
    check.add_argument("--ignore", default="wall,floor,ceiling", help="comma-separated classes with no predicate")
    check.add_argument("--merge", default=None, metavar="PRED[,PRED]|all",
                       help="also merge these taxonomy groups of kinds into one predicate (is_table_or_desk), or "
                            "'all' (default: classes listed separately stay separate; only synonyms merge)")
    check.add_argument("--matrix", action="store_true", help="print the full predicate x label matrix")
    check.add_argument("--predicate", action="append", default=None, help="only this predicate (repeatable)")
    check.add_argument("--json", action="store_true", help="machine-readable output")


def _table(args: argparse.Namespace):  # noqa: ANN202
    from pathlib import Path

    import yaml

    from sgbelief.fusion.compatibility import SubsumptionTable

    path = Path(args.vocab)
    ignore = [s for s in (args.ignore or "").split(",") if s.strip()]
    if path.suffix in (".yaml", ".yml") and path.exists():
        head = yaml.safe_load(path.read_text(encoding="utf-8"))
        fmt = head.get("format") if isinstance(head, dict) else None
        if fmt == "sgbelief.vocabulary":
            return SubsumptionTable.from_yaml(path)
        if fmt == "sgbelief.cg_vocabulary":
            from sgbelief.adapters.conceptgraphs.vocab import ClassVocabulary

            table = ClassVocabulary.from_yaml(path).table()
            if table is None:
                raise FileNotFoundError(f"{path}: names no subsumption table")
            return table
    if not path.suffix and not path.exists():
        from sgbelief.resources import config_dir

        if not (config_dir() / "vocab" / "classes" / f"{args.vocab}.txt").exists() and \
                (config_dir() / "vocab" / f"{args.vocab}.yaml").exists():
            return SubsumptionTable.shipped(args.vocab)  # a hand-written shipped table (scannet, kitti360)
    from sgbelief.fusion.open_vocab import derive_table

    merge: bool | list[str] = False
    if args.merge:
        merge = True if args.merge.strip().lower() == "all" else [m.strip() for m in args.merge.split(",") if m.strip()]
    return derive_table(args.vocab, args.taxonomy, args.mapping, ignore=ignore, merge=merge)


def run(args: argparse.Namespace) -> int:
    from sgbelief.fusion.open_vocab import describe, verdict_matrix

    table = _table(args)
    preds = args.predicate or table.predicates
    for p in preds:
        table.require(p)
    all_preds, labels, rows = verdict_matrix(table)
    keep = [all_preds.index(p) for p in preds]
    if args.json:
        out = {"name": table.name, "labels": labels,
               "verdicts": {all_preds[i]: dict(zip(labels, rows[i])) for i in keep},
               "classes": {all_preds[i]: table.specs[all_preds[i]].aliases for i in keep}}
        print(json.dumps(out, indent=1, ensure_ascii=False))
        return 0
    print(f"table {table.name!r}: {len(all_preds)} predicates x {len(labels)} geometric labels "
          f"(T corroborates, ⊥ contradicts, ∅ no claim; a claim with confidence >= 0.5)")
    if table.ambiguous_labels:
        print(f"ambiguous labels (∅ everywhere): {', '.join(sorted(table.ambiguous_labels))}")
    if args.matrix:
        width = max(len(p) for p in preds)
        for j, lab in enumerate(labels):
            print(" " * (width + 1) + "|" * j + lab)
        print(" " * (width + 1) + "|" * len(labels))
        for i in keep:
            print(f"{all_preds[i]:<{width}} " + "".join(rows[i]))
        return 0
    lines = describe(table)
    for i in keep:
        print(lines[i])
    undecidable = [all_preds[i] for i in keep if "T" not in rows[i] and "⊥" not in rows[i]]
    if undecidable:
        print(f"no geometric label decides: {', '.join(undecidable)}")
    return 0
