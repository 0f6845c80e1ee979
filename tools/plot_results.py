#!/usr/bin/env python3
"""Plots of a reproduction sweep (docs/reproduce.md).

    python3 tools/plot_results.py OUT_DIR [--window 30]

Reads OUT_DIR/summary.csv (written by examples/reproduce) and the training logs
OUT_DIR/runs/<run>.csv it names (docs/formats.md), and draws into OUT_DIR/plots/:

- <task>_test_loss.png: the paper's figures. Test loss against epoch, smoothed with a trailing
  moving average (30 epochs, like the paper; the first epochs average what exists so far), one
  panel per complexity (poles / rc / target), log y. Lines are the mean over seeds, bands the
  mean ± one standard deviation (cut at the panel's bottom where mean − std ≤ 0).
- <task>_loss_vs_time.png: the same curves against cumulative training seconds (speed against
  error: a method that is cheaper per epoch moves left).
- speed_vs_error.png: final test loss against mean seconds per epoch, one point per run, for
  the hardest setting of each task.
- update_norm.png: update_norm2 (the squared norm of the vector fed to the optimizer, before
  clipping, averaged over the epoch's mini-batches) per epoch, log y, for the hardest setting
  of each task, like the paper's "update size" panel. These values spread over orders of
  magnitude, so the line is the geometric mean over seeds and the band ×/÷ the geometric
  standard deviation (mean ± std of log10).

Colours are fixed per method (R red, M blue, C green, S grey, N purple) and line styles per
clip mode (norm solid, value dashed, none dotted) in every figure. A run that stopped on a
non-finite value (status "stopped") is marked with a cross at its last epoch, on its own
curve, and counted in the title: the mean after that epoch covers the other seeds only. Every PNG is written to a
temporary file and renamed, so a reader never sees half a picture.
"""
import argparse
import csv
import math
import os
import signal
import sys
import tempfile
import textwrap
import warnings

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    from matplotlib.lines import Line2D
    import numpy as np
except ImportError as error:  # a missing package is a setup problem, not a bug: no traceback
    sys.exit(f"plot_results: {sys.executable} cannot import {error.name or 'matplotlib'}; "
             "install python3-matplotlib (Debian) or run this script with a python3 that has it")

METHOD_COLOURS = {"R": "#d62728", "M": "#1f77b4", "C": "#2ca02c", "S": "#7f7f7f", "N": "#9467bd"}
METHOD_NAMES = {"R": "R (regular)", "M": "M (modified)", "C": "C (combined)", "S": "S (stopped)",
                "N": "N (network only)"}
METHOD_ORDER = ["R", "M", "C", "S", "N"]
CLIP_STYLES = {"norm": "-", "value": "--", "none": ":"}
CLIP_MARKERS = {"norm": "o", "value": "s", "none": "^"}
CLIP_ORDER = ["none", "value", "norm"]
TASK_ORDER = ["cartpole", "guidance", "quantum", "chain"]
PANEL_SIZE = (5.2, 3.9)  # inches
# One panel alone is narrower than the titles and legends written for a row of them.
MIN_WIDTH = 8.5  # inches
# title of a complexity panel; whether a smaller value is harder
TASKS = {
    "cartpole": ("Number of poles: {}", False),
    "guidance": ("Regularization: rc = {}", True),
    "quantum": ("Target state: {}", False),
    "chain": ("Links of the chain: {}", False),
}


def fail(message):
    print(f"plot_results: {message}", file=sys.stderr)
    sys.exit(1)


def number(text):
    return float(text) if text not in ("", None) else math.nan


def read_log(path):
    """The training log of one run as arrays: epoch, test_loss, update_norm2, seconds."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    keys = ["epoch", "test_loss", "update_norm2", "seconds"]
    return {k: np.array([number(r[k]) for r in rows], dtype=float) for k in keys}


def trailing_average(y, window):
    """y[i] ↦ mean(y[max(0, i−window+1) .. i])."""
    c = np.concatenate([[0.0], np.cumsum(y)])
    i = np.arange(1, len(y) + 1)
    lo = np.maximum(0, i - window)
    return (c[i] - c[lo]) / (i - lo)


def mean_std(curves):
    """Mean and standard deviation over runs of curves of possibly different lengths (runs
    that stopped early contribute to the epochs they have)."""
    length = max(len(c) for c in curves)
    stacked = np.full((len(curves), length), np.nan)
    for k, c in enumerate(curves):
        stacked[k, : len(c)] = c
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(stacked, axis=0), np.nanstd(stacked, axis=0)


def save(fig, path, stops=0):
    directory = os.path.dirname(path)
    fd, temporary = tempfile.mkstemp(prefix=".tmp.", suffix=".png", dir=directory)
    os.close(fd)
    try:
        # "tight" grows the picture to whatever sticks out (a legend below the panels, a long
        # title) instead of cutting it off.
        fig.savefig(temporary, format="png", dpi=110, bbox_inches="tight", pad_inches=0.15)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    finally:
        plt.close(fig)
        if os.path.exists(temporary):
            os.unlink(temporary)
    marked = f" ({stops} run(s) stopped on a non-finite value, marked ×)" if stops else ""
    print(f"plot_results: wrote {path}{marked}")


def grid_shape(n):
    if n <= 3:
        return 1, n
    cols = math.ceil(math.sqrt(n))
    return math.ceil(n / cols), cols


def panels(rows, cols):
    width = max(PANEL_SIZE[0] * cols, MIN_WIDTH)
    return plt.subplots(rows, cols, figsize=(width, PANEL_SIZE[1] * rows), squeeze=False)


def finish_figure(fig, title, handles):
    """Title above and legend below the panels, both broken into lines that fit the width."""
    width = fig.get_figwidth()
    fig.suptitle("\n".join(textwrap.wrap(title, width=int(width * 9))))
    # A legend entry needs about 1.9 inches; more rows rather than a legend wider than the
    # figure.
    ncol = max(1, min(len(handles), int(width / 1.9)))
    # Hung below the figure: tight_layout leaves no room for it, savefig's tight box does.
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0), ncol=ncol,
               frameon=False)
    fig.tight_layout()


def legend_handles(methods, clips, stops=0):
    handles = [Line2D([], [], color=METHOD_COLOURS[m], lw=2, label=METHOD_NAMES[m])
               for m in METHOD_ORDER if m in methods]
    if len(clips) > 1 or clips != {"norm"}:
        handles += [Line2D([], [], color="black", ls=CLIP_STYLES[c], label=f"clip {c}")
                    for c in CLIP_ORDER if c in clips]
    if stops:
        handles.append(Line2D([], [], color="black", ls="none", marker="x",
                              label="run stopped on a non-finite value"))
    return handles


def mark_stops(ax, members, curves, colour):
    """A cross at the last epoch of every member run that stopped, on that run's own curve
    (curves[i] = (x, y) of members[i]); returns how many."""
    count = 0
    for m, (x, y) in zip(members, curves):
        if m["status"] != "stopped":
            continue
        if len(y) and np.isfinite(y[-1]):
            ax.plot([x[-1]], [y[-1]], marker="x", ms=7, mew=1.6, color=colour, ls="none")
        count += 1
    return count


def stops_text(stops):
    return f"; {stops} run(s) stopped on a non-finite value (×)" if stops else ""


def sort_complexities(task, values):
    harder_when_smaller = TASKS[task][1]
    return sorted(values, key=lambda v: -float(v) if harder_when_smaller else float(v))


def load(out):
    summary_path = os.path.join(out, "summary.csv")
    if not os.path.exists(summary_path):
        fail(f"no {summary_path}; run examples/reproduce first")
    with open(summary_path, newline="") as f:
        summary = list(csv.DictReader(f))
    runs = []
    for row in summary:
        path = os.path.join(out, "runs", row["run"] + ".csv")
        if not os.path.exists(path):
            print(f"plot_results: warning: {path} is missing; run skipped", file=sys.stderr)
            continue
        log = read_log(path)
        if len(log["epoch"]) == 0:
            continue  # stopped before the first epoch: nothing to draw
        runs.append({**row, "log": log})
    return runs


def groups(runs, task, complexity):
    """(method, clip) -> runs of one task and complexity, in legend order."""
    found = {}
    for r in runs:
        if r["task"] == task and r["complexity"] == complexity:
            found.setdefault((r["method"], r["clip"]), []).append(r)
    order = lambda key: (METHOD_ORDER.index(key[0]) if key[0] in METHOD_ORDER else 99,
                         CLIP_ORDER.index(key[1]) if key[1] in CLIP_ORDER else 99)
    return [(key, found[key]) for key in sorted(found, key=order)]


def finish_axes(ax, integer_x):
    """Plain tick labels when the log axis spans less than a decade; whole epochs on x."""
    low, high = ax.get_ylim()
    if low > 0 and high / low < 10:
        ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(6))
        ax.yaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter(useOffset=False))
        ax.yaxis.set_minor_locator(matplotlib.ticker.NullLocator())
    if integer_x:
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.grid(True, which="major", alpha=0.3)
    ax.grid(True, which="minor", alpha=0.1)


def band(ax, x, mean, std, colour, floor):
    if np.all(std == 0):
        return
    lower = np.where(mean - std > floor, mean - std, floor)
    ax.fill_between(x, lower, mean + std, color=colour, alpha=0.15, lw=0)


def positive_floor(values):
    positive = [v[np.isfinite(v) & (v > 0)] for v in values]
    positive = np.concatenate(positive) if positive else np.array([])
    return 0.5 * positive.min() if positive.size else 1e-12


def curve_figure(runs, task, window, against_time):
    complexities = sort_complexities(task, {r["complexity"] for r in runs if r["task"] == task})
    fig, axes = panels(*grid_shape(len(complexities)))
    methods, clips, seeds = set(), set(), set()
    stops = 0

    def own_curve(m):
        y = trailing_average(m["log"]["test_loss"], window)
        x = np.cumsum(m["log"]["seconds"]) if against_time else np.arange(1, len(y) + 1)
        return x, y

    for ax, complexity in zip(axes.flat, complexities):
        lines = []
        for (method, clip), members in groups(runs, task, complexity):
            methods.add(method)
            clips.add(clip)
            seeds.add(len(members))
            curves = [own_curve(m) for m in members]
            mean, std = mean_std([y for _, y in curves])
            if against_time:
                x, _ = mean_std([x for x, _ in curves])
            else:
                x = np.arange(1, len(mean) + 1)
            lines.append((x, mean, std, METHOD_COLOURS.get(method, "black"),
                          CLIP_STYLES.get(clip, "-.")))
            stops += mark_stops(ax, members, curves, METHOD_COLOURS.get(method, "black"))
        floor = positive_floor([line[1] for line in lines])
        for x, mean, std, colour, style in lines:
            band(ax, x, mean, std, colour, floor)
            ax.plot(x, mean, color=colour, ls=style, lw=1.4)
        ax.set_yscale("log")
        ax.set_title(TASKS[task][0].format(complexity))
        ax.set_xlabel("training seconds (cumulative)" if against_time else "epoch")
        ax.set_ylabel(f"test loss ({window}-epoch moving average)")
        finish_axes(ax, not against_time)
    for ax in list(axes.flat)[len(complexities):]:
        ax.set_visible(False)
    seeds_text = (f"{min(seeds)}" if min(seeds) == max(seeds) else f"{min(seeds)}–{max(seeds)}")
    what = "against training time" if against_time else "against epoch"
    finish_figure(fig, f"{task}: test loss {what}, mean ± std over {seeds_text} seed(s)"
                  + stops_text(stops), legend_handles(methods, clips, stops))
    return fig, stops


def hardest(runs, task):
    complexities = sort_complexities(task, {r["complexity"] for r in runs if r["task"] == task})
    return complexities[-1]


def update_norm_figure(runs, tasks):
    fig, axes = panels(1, len(tasks))
    methods, clips = set(), set()
    stops = 0
    for ax, task in zip(axes.flat, tasks):
        complexity = hardest(runs, task)
        lines = []
        for (method, clip), members in groups(runs, task, complexity):
            methods.add(method)
            clips.add(clip)
            # Update sizes spread over orders of magnitude: average their logarithms.
            with np.errstate(divide="ignore"):
                logs = [np.log10(np.where(m["log"]["update_norm2"] > 0,
                                          m["log"]["update_norm2"], np.nan)) for m in members]
            mean, std = mean_std(logs)
            lines.append((mean, std, METHOD_COLOURS.get(method, "black"),
                          CLIP_STYLES.get(clip, "-.")))
            sizes = [m["log"]["update_norm2"] for m in members]
            stops += mark_stops(ax, members, [(np.arange(1, len(y) + 1), y) for y in sizes],
                                METHOD_COLOURS.get(method, "black"))
        for mean, std, colour, style in lines:
            x = np.arange(1, len(mean) + 1)
            if not np.all(np.nan_to_num(std) == 0):
                ax.fill_between(x, 10 ** (mean - std), 10 ** (mean + std), color=colour,
                                alpha=0.15, lw=0)
            ax.plot(x, 10 ** mean, color=colour, ls=style, lw=1.2)
        ax.set_yscale("log")
        ax.set_title(f"{task}, {TASKS[task][0].format(complexity)}")
        ax.set_xlabel("epoch")
        ax.set_ylabel("update size ‖update‖² before clipping")
        finish_axes(ax, True)
    finish_figure(fig, "Update size (update_norm2) at the hardest setting: geometric mean ×/÷ "
                  "geometric std over seeds" + stops_text(stops),
                  legend_handles(methods, clips, stops))
    return fig, stops


def speed_figure(runs, tasks):
    fig, axes = panels(1, len(tasks))
    methods, clips = set(), set()
    for ax, task in zip(axes.flat, tasks):
        complexity = hardest(runs, task)
        for (method, clip), members in groups(runs, task, complexity):
            methods.add(method)
            clips.add(clip)
            x = [number(m["mean_seconds_per_epoch"]) for m in members]
            y = [number(m["final_test_loss"]) for m in members]
            ax.scatter(x, y, color=METHOD_COLOURS.get(method, "black"),
                       marker=CLIP_MARKERS.get(clip, "x"), s=28, alpha=0.8)
        ax.set_yscale("log")
        ax.set_title(f"{task}, {TASKS[task][0].format(complexity)}")
        ax.set_xlabel("training seconds per epoch")
        ax.set_ylabel("final test loss")
        finish_axes(ax, False)
    handles = [Line2D([], [], color=METHOD_COLOURS[m], marker="o", ls="", label=METHOD_NAMES[m])
               for m in METHOD_ORDER if m in methods]
    handles += [Line2D([], [], color="black", marker=CLIP_MARKERS[c], ls="", label=f"clip {c}")
                for c in CLIP_ORDER if c in clips]
    finish_figure(fig, "Speed against error: one point per run", handles)
    return fig


def stop(signal_number, _frame):
    # SIGTERM and SIGHUP end Python without unwinding; as an exception they run save()'s
    # cleanup, so an interrupted plot leaves no temporary figure behind.
    raise SystemExit(128 + signal_number)


def main():
    for signal_number in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signal_number, stop)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", help="the sweep's output directory (holds summary.csv and runs/)")
    parser.add_argument("--window", type=int, default=30,
                        help="trailing moving-average window in epochs (default 30, as the paper)")
    args = parser.parse_args()
    if args.window < 1:
        parser.error(f"--window {args.window}: expected an integer >= 1")
    runs = load(args.out)
    if not runs:
        fail(f"{os.path.join(args.out, 'summary.csv')} lists no finished run with a logged epoch")
    plots = os.path.join(args.out, "plots")
    os.makedirs(plots, exist_ok=True)
    tasks = [t for t in TASK_ORDER if any(r["task"] == t for r in runs)]
    for task in tasks:
        fig, stops = curve_figure(runs, task, args.window, False)
        save(fig, os.path.join(plots, f"{task}_test_loss.png"), stops)
        fig, stops = curve_figure(runs, task, args.window, True)
        save(fig, os.path.join(plots, f"{task}_loss_vs_time.png"), stops)
    save(speed_figure(runs, tasks), os.path.join(plots, "speed_vs_error.png"))
    fig, stops = update_norm_figure(runs, tasks)
    save(fig, os.path.join(plots, "update_norm.png"), stops)


if __name__ == "__main__":
    main()
