#!/usr/bin/env python3
"""Method A against method B, seed by seed, from a sweep's summary.csv, as Markdown.

    python3 tools/compare_methods.py SUMMARY_CSV [--pair C,R] [--pair M,R] [--task cartpole]

For every task, complexity and clip mode where both methods ran, one row: the seeds of each
method (how many stopped on a non-finite value), the median final test loss with its
[min, max] over seeds, the ratio of the medians (B over A: above 1 means A's median is lower),
and whether the two ranges overlap, and where. Every claim in docs/results.md that one method
"beats" another quotes a row of this table and names the file it read.

A run that stopped on a non-finite value (status `stopped`, examples/reproduce) is a result:
it is neither dropped nor redone. It enters the median and the range with the test loss of
its last logged epoch (the last parameters whose evaluation was finite), and the seeds
column counts it, e.g. "3 (1 stopped)".
"""
import argparse
import csv
import statistics
import sys

METHOD_ORDER = "RMCSN"
CLIP_ORDER = ["none", "value", "norm"]


def fmt(x):
    return f"{x:.4g}"


def describe(values):
    text = fmt(statistics.median(values))
    if len(values) > 1:
        text += f" [{fmt(min(values))}, {fmt(max(values))}]"
    return text


def seeds(members):
    stopped = sum(r["status"] != "ok" for r in members)
    return f"{len(members)} ({stopped} stopped)" if stopped else str(len(members))


def ranges(a_name, a, b_name, b):
    """Where the [min, max] ranges of two methods' final losses lie against each other."""
    if len(a) < 2 and len(b) < 2:
        return "one seed each: no range"
    if max(a) < min(b):
        return f"disjoint: {a_name}'s worst {fmt(max(a))} < {b_name}'s best {fmt(min(b))}"
    if max(b) < min(a):
        return f"disjoint: {b_name}'s worst {fmt(max(b))} < {a_name}'s best {fmt(min(a))}"
    low, high = max(min(a), min(b)), min(max(a), max(b))
    return f"overlap on [{fmt(low)}, {fmt(high)}]"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("summary", help="a sweep's summary.csv")
    parser.add_argument("--pair", action="append", default=[],
                        help="A,B: compare method A with method B (repeatable; default C,R)")
    parser.add_argument("--task", help="only this task")
    args = parser.parse_args()
    pairs = []
    for text in args.pair or ["C,R"]:
        parts = text.split(",")
        if len(parts) != 2 or any(p not in METHOD_ORDER for p in parts) or parts[0] == parts[1]:
            sys.exit(f"compare_methods: --pair '{text}' is not two different methods A,B "
                     f"out of {', '.join(METHOD_ORDER)}")
        pairs.append(parts)
    try:
        with open(args.summary, newline="") as f:
            runs = list(csv.DictReader(f))
    except OSError as e:
        sys.exit(f"compare_methods: cannot read {args.summary}: {e.strerror}")
    needed = {"task", "complexity", "method", "clip", "final_test_loss", "status"}
    if not runs or not needed <= set(runs[0]):
        sys.exit(f"compare_methods: {args.summary} is not a summary.csv with runs "
                 f"(expected the columns {', '.join(sorted(needed))})")

    groups = {}
    for r in runs:
        if args.task and r["task"] != args.task:
            continue
        key = (r["task"], float(r["complexity"]), r["clip"])
        groups.setdefault(key, {}).setdefault(r["method"], []).append(r)
    if not groups:
        sys.exit(f"compare_methods: no run of task '{args.task}' in {args.summary}")

    def order(key):
        task, complexity, clip = key
        return (task, -complexity if task == "guidance" else complexity, CLIP_ORDER.index(clip))

    considered = [r for r in runs if not args.task or r["task"] == args.task]
    stopped = [r.get("run", "?") for r in considered if r["status"] != "ok"]
    print(f"Source: `{args.summary}`, final test loss. {len(considered)} runs, "
          f"{len(stopped)} of them stopped on a non-finite value"
          + (f" ({', '.join(stopped)})." if stopped else ".") + "\n")
    for a_name, b_name in pairs:
        print(f"| task | complexity | clip | {a_name} seeds | {a_name}: median [min, max] | "
              f"{b_name} seeds | {b_name}: median [min, max] | {b_name} ÷ {a_name} (medians) | "
              "ranges |")
        print("|---|---|---|---:|---:|---:|---:|---:|---|")
        for key in sorted(groups, key=order):
            by_method = groups[key]
            if a_name not in by_method or b_name not in by_method:
                continue
            a = [float(r["final_test_loss"]) for r in by_method[a_name]]
            b = [float(r["final_test_loss"]) for r in by_method[b_name]]
            ratio = statistics.median(b) / statistics.median(a) if statistics.median(a) else float("inf")
            task, complexity, clip = key
            print(f"| {task} | {complexity:g} | {clip} | {seeds(by_method[a_name])} | {describe(a)} "
                  f"| {seeds(by_method[b_name])} | {describe(b)} | {ratio:.3g} | "
                  f"{ranges(a_name, a, b_name, b)} |")
        print()


if __name__ == "__main__":
    main()
