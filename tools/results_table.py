#!/usr/bin/env python3
"""The results table of a reproduction sweep as Markdown, for docs/results.md.

    python3 tools/results_table.py OUT_DIR [--initial]

Reads OUT_DIR/summary.csv (examples/reproduce) and prints one row per task, complexity,
method and clip mode: the number of seeds, the median final test loss with its [min, max]
over seeds, the median minimum test loss, the mean training seconds per epoch and the C/R
ratio of those seconds. With --initial it also reads the first logged epoch of every run
(OUT_DIR/runs/<run>.csv) and prints the median test loss after epoch 1. Numbers are printed
as they are in the files (4 significant digits), so the table in the docs is never typed by
hand.
"""
import argparse
import csv
import os
import statistics
import sys

METHOD_ORDER = "RMCSN"
CLIP_ORDER = ["none", "value", "norm"]


def first_test_loss(out, run):
    with open(os.path.join(out, "runs", run + ".csv"), newline="") as f:
        rows = csv.DictReader(f)
        return float(next(rows)["test_loss"])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("--initial", action="store_true")
    args = parser.parse_args()
    path = os.path.join(args.out, "summary.csv")
    try:
        with open(path, newline="") as f:
            runs = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"results_table: cannot read {path}: {e.strerror}")
    if not runs:
        sys.exit(f"results_table: {path} lists no run")

    groups = {}
    for r in runs:
        key = (r["task"], float(r["complexity"]), r["method"], r["clip"])
        groups.setdefault(key, []).append(r)

    def order(key):
        task, complexity, method, clip = key
        hard_when_small = task == "guidance"
        return (task, -complexity if hard_when_small else complexity,
                METHOD_ORDER.index(method), CLIP_ORDER.index(clip))

    seconds_of = {k: statistics.mean(float(r["mean_seconds_per_epoch"]) for r in v)
                  for k, v in groups.items()}
    header = ["task", "complexity", "method", "clip", "seeds"]
    if args.initial:
        header.append("test loss, epoch 1")
    header += ["final test loss: median [min, max]", "min test loss (median)", "s/epoch",
               "s/epoch ÷ R"]
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---" if i < 4 else "---:" for i in range(len(header))) + "|")
    for key in sorted(groups, key=order):
        task, complexity, method, clip = key
        members = groups[key]
        finals = [float(r["final_test_loss"]) for r in members]
        mins = [float(r["min_test_loss"]) for r in members]
        spread = f" [{min(finals):.4g}, {max(finals):.4g}]" if len(finals) > 1 else ""
        regular = seconds_of.get((task, complexity, "R", clip))
        ratio = f"{seconds_of[key] / regular:.2f}" if regular else "–"
        stopped = sum(r["status"] != "ok" for r in members)
        note = f" ({stopped} stopped)" if stopped else ""
        row = [task, f"{complexity:g}", method, clip, f"{len(members)}{note}"]
        if args.initial:
            row.append(f"{statistics.median(first_test_loss(args.out, r['run']) for r in members):.4g}")
        row += [f"{statistics.median(finals):.4g}{spread}", f"{statistics.median(mins):.4g}",
                f"{seconds_of[key]:.4f}", ratio]
        print("| " + " | ".join(row) + " |")


if __name__ == "__main__":
    main()
