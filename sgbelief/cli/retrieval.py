"""``sgbelief retrieval``: compound-query retrieval F1 per operator (Table 3, full-pool columns), and
for a suite folder written by ``sgbelief bench`` Table 4: the operator against the monolithic prompt.

Two sources:
  ScanNet scene folders:  --scenes DIR --events EVENTS.jsonl --vocab VOCAB
  simulated suites:       --suite DIR [--suite DIR ...] --vocab VOCAB   (nodes.json, events.jsonl, truth.json)
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sgbelief.cli import _console as console


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_argument_group("source (one of)")
    src.add_argument("--scenes", metavar="DIR", help="ScanNet v2 scene folders (or one scene folder); no default")
    src.add_argument("--suite", metavar="DIR", action="append", default=[],
                     help="simulated suite folder with nodes.json, events.jsonl, truth.json (repeatable; e.g. "
                          "results/bench/data/outdoor written by 'sgbelief bench'); no default")
    parser.add_argument("--events", metavar="EVENTS.jsonl", help="event log replayed over the ScanNet scenes (required with --scenes; no default)")
    parser.add_argument("--vocab", metavar="VOCAB", default=None,
                        help="vocabulary YAML or shipped name (scannet | kitti360); default: scannet for --scenes and indoor "
                             "suites, kitti360 for outdoor suites")
    parser.add_argument("--labels", metavar="TSV", default=None,
                        help="scannetv2-labels.combined.tsv (default: found next to / above --scenes)")
    parser.add_argument("--queries", metavar="NAME_OR_YAML", default=None,
                        help="named-query set: scannet | kitti360 | a YAML file (default: the vocabulary's)")
    parser.add_argument("--operators", default="overwrite,majority,naive_bayes,refined,cal,comod",
                        help="comma-separated operator names (default: all six)")
    parser.add_argument("--operator-config", metavar="YAML", default=None, help="operator configuration file (default: sgbelief/configs/operators/default.yaml)")
    parser.add_argument("--channel", choices=("scannet", "recorded"), default="scannet",
                        help="ScanNet geometric channel: mesh labels (default) or the events' recorded labels")
    parser.add_argument("--tau", type=float, default=0.5, help="retrieval threshold: retrieved when P > tau, strictly (default: %(default)s)")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table (default: a table)")
    parser.add_argument("--out", metavar="FILE", default=None, help="also write the scores as JSON to FILE (default: none)")
    parser.add_argument("--compound-operator", metavar="NAME", default="comod",
                        help="operator compared with the monolithic compound prompt (Table 4) when a --suite folder "
                             "holds monolithic.jsonl (default: %(default)s)")
    parser.add_argument("--no-monolithic", action="store_true",
                        help="skip Table 4 (the monolithic-prompt comparison) for --suite folders (default: print it)")
    parser.add_argument("--workers", type=int, default=1,
                        help="evaluate the (source, operator) cells in parallel processes (same output as serial; "
                             "default: %(default)s)")
    parser.add_argument("--executor", choices=["local", "ray"], default="local",
                        help="local process pool, or a Ray cluster (pip install 'sgbelief[ray]'; RAY_ADDRESS; "
                             "default: %(default)s)")


def run(args: argparse.Namespace) -> int:
    from sgbelief.eval.retrieval import RetrievalSource, evaluate_retrieval, evaluate_sources, format_scores

    if bool(args.scenes) == bool(args.suite):
        print("sgbelief retrieval: error: give either --scenes (with --events) or --suite", file=sys.stderr)
        return 2
    if args.workers < 0:
        print("sgbelief retrieval: error: --workers must be >= 0", file=sys.stderr)
        return 2
    operators = [o.strip() for o in args.operators.split(",") if o.strip()]
    sources = []
    if args.scenes:
        if not args.events:
            print("sgbelief retrieval: error: --scenes needs --events EVENTS.jsonl", file=sys.stderr)
            return 2
        sources.append(RetrievalSource("scannet", str(args.scenes), events=str(args.events), vocab=args.vocab,
                                       queries=args.queries, labels=args.labels, channel=args.channel))
    sources += [RetrievalSource("suite", str(suite), vocab=args.vocab, queries=args.queries) for suite in args.suite]
    if args.workers > 1 or args.executor != "local":
        # one task per (source, operator), results back in input order: the serial output
        results = evaluate_sources(sources, operators, tau=args.tau, operator_config=args.operator_config,
                                   workers=args.workers, executor=args.executor)
    else:
        results = []
        with console.progress(len(sources) * len(operators), desc="retrieval", unit="run") as bar:
            for src in sources:
                data = src.load()
                results.append((data.name, evaluate_retrieval(data, operators, tau=args.tau,
                                                              operator_config=args.operator_config,
                                                              progress=lambda _name: bar.update(1))))
    report = []
    for src, (name, scores) in zip(sources, results):
        report.append({"source": name, "tau": args.tau, "scores": [s.to_dict() for s in scores]})
        if not args.json:
            print(format_scores(scores, title=f"{name}  (tau = {args.tau})"))
            print()
        if src.kind == "suite" and not args.no_monolithic:
            from sgbelief.eval.compound_table import format_text, suite_folder_table

            table4 = suite_folder_table(src.path, vocab=args.vocab, queries=args.queries, operator=args.compound_operator,
                                        operator_config=args.operator_config, tau=args.tau)
            if table4 is not None:
                report[-1]["compound_table"] = table4
                if not args.json:
                    print(format_text(table4, title=f"{name}: component beliefs against one monolithic compound "
                                                    f"prompt (Table 4)"))
                    print()
    if args.json:
        json.dump(report, sys.stdout, indent=2)
        sys.stdout.write("\n")
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    return 0
