#!/usr/bin/env python3
"""How far the update size of each run swings, as Markdown, for docs/results.md.

    python3 tools/update_norm_spread.py OUT_DIR [--skip EPOCHS]

Reads every OUT_DIR/runs/<run>.csv (the training logs of a reproduction sweep) and prints one
row per task, complexity and method: over the epochs after the first --skip (default 10), the
5th, 50th and 95th percentiles of log10(update_norm2) pooled over seeds, the spread from the
5th to the 95th percentile in decades, the largest value, and how many epochs logged an
update_norm2 of inf (a finite norm whose square overflowed; docs/formats.md). update_norm2 is
the squared norm of the vector fed to the optimizer before clipping, the paper's "update size".
"""
import csv
import glob
import math
import os
import sys
from collections import defaultdict


def percentile(sorted_values, q):
    return sorted_values[int(round(q * (len(sorted_values) - 1)))]


def main():
    args = sys.argv[1:]
    if not args or args[0].startswith("-"):
        sys.exit(__doc__)
    out, skip = args[0], 10
    if "--skip" in args:
        skip = int(args[args.index("--skip") + 1])
    pooled, overflowed, seeds = defaultdict(list), defaultdict(int), defaultdict(set)
    for path in sorted(glob.glob(os.path.join(out, "runs", "*.csv"))):
        name = os.path.basename(path)[: -len(".csv")]
        if name.endswith(".partial"):
            continue
        description = {}
        with open(os.path.join(out, "runs", name + ".run")) as f:
            for line in f:
                key, _, value = line.strip().partition("=")
                description[key] = value
        key = (description["task"], description["complexity"], description["method"])
        seeds[key].add(description["seed"])
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                if int(row["epoch"]) <= skip or row["update_norm2"] == "":
                    continue
                value = float(row["update_norm2"])
                if math.isinf(value):
                    overflowed[key] += 1
                elif value > 0:
                    pooled[key].append(math.log10(value))
    print(f"Source: `{out}/runs/*.csv`, epochs after {skip}, log10 of update_norm2.\n")
    print("| task | complexity | method | seeds | p5 | median | p95 | p95 − p5 (decades) | max | inf |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|")
    order = "RMCSN"
    for key in sorted(pooled, key=lambda k: (k[0], float(k[1]), order.find(k[2]))):
        values = sorted(pooled[key])
        p5, p50, p95 = (percentile(values, q) for q in (0.05, 0.5, 0.95))
        print(f"| {key[0]} | {key[1]} | {key[2]} | {len(seeds[key])} | {p5:.1f} | {p50:.1f} | "
              f"{p95:.1f} | {p95 - p5:.1f} | {values[-1]:.1f} | {overflowed[key]} |")


if __name__ == "__main__":
    main()
