#!/usr/bin/env python3
"""Speed-against-error plot of examples/accuracy (docs/benchmarks.md).

    python3 tools/plot_accuracy.py ACCURACY_CSV OUT_PNG

Reads the CSV that `accuracy --csv FILE` writes (columns sim, sweep, scalar, steps, nx, h, ms,
state_error, grad_error, loss_error) and draws, log-log:

- top row: relative error of the final state (left) and of the gradient g_R (middle) against
  the milliseconds of one forward pass + one Full sweep of a batch of 8, one curve per
  simulator, sweep (time step "dt" or grid "nx") and precision (double solid, float dashed);
- bottom row: the same errors against the step (or grid spacing) relative to the paper's
  value, with reference slopes 1 and 2 (first-order Euler, second-order Crank–Nicolson and
  3-point Laplacian);
- right column: float against double at the paper's settings, error against the horizon
  (fraction of the paper's number of steps), final state (top) and g_R (bottom);
- third row: the cart pole's integrator axis (sweeps "sie", "rk2", "rk4": semi-implicit Euler,
  Heun, RK4 at a fixed control rate): the error-against-time front of each integrator for the
  final state and g_R, with the paper's accuracy (semi-implicit Euler at h = 0.01) as a
  horizontal line, and the errors against h with slopes 1, 2 and 4.

Uses matplotlib's Agg backend (Debian: python3-matplotlib). The PNG is written to a temporary
file and renamed, so a reader never sees half a picture. Bad arguments: message, exit 2.
"""
import csv
import os
import sys
import tempfile

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError as error:  # a missing package is a setup problem, not a bug: no traceback
    sys.exit(f"plot_accuracy: {sys.executable} cannot import {error.name or 'matplotlib'}; "
             "install python3-matplotlib (Debian) or run this script with a python3 that has it")

SIM_COLOURS = {"cartpole": "#d62728", "guidance": "#1f77b4", "quantum": "#2ca02c"}
SWEEP_MARKERS = {"dt": "o", "nx": "s"}
SCALAR_STYLES = {"double": "-", "float": "--"}
INTEGRATORS = {"sie": ("semi-implicit Euler", "#d62728"), "rk2": ("Heun (RK2)", "#ff7f0e"),
               "rk4": ("RK4", "#9467bd")}
# The paper's step (dt) or grid spacing (dx) for each sweep: the x axis of the bottom row is
# h divided by this.
PAPER_H = {("cartpole", "dt"): 0.01, ("guidance", "dt"): 4.0 / 60.0,
           ("quantum", "dt"): 0.0625, ("quantum", "nx"): 2.0 / 33.0}
COLUMNS = ["sim", "sweep", "scalar", "steps", "nx", "h", "ms", "state_error", "grad_error",
           "loss_error"]


def fail(message):
    print(f"plot_accuracy: {message}", file=sys.stderr)
    sys.exit(2)


def read(path):
    try:
        with open(path, newline="") as handle:
            reader = csv.DictReader(handle)
            missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
            if missing:
                fail(f"{path}: missing columns {', '.join(missing)}; expected the CSV of "
                     "`accuracy --csv`")
            rows = []
            for number, row in enumerate(reader, start=2):
                try:
                    for key in ("h", "ms", "state_error", "grad_error", "loss_error"):
                        row[key] = float(row[key])
                    row["steps"] = int(row["steps"])
                except ValueError:
                    fail(f"{path}:{number}: a value is not a number")
                rows.append(row)
    except OSError as error:
        fail(f"cannot read '{path}': {error.strerror}")
    if not rows:
        fail(f"{path}: no rows")
    return rows


def curves(rows, sweep_filter):
    grouped = {}
    for row in rows:
        if not sweep_filter(row["sweep"]):
            continue
        grouped.setdefault((row["sim"], row["sweep"], row["scalar"]), []).append(row)
    for key in grouped:
        grouped[key].sort(key=lambda r: r["h"])
    return grouped


def main():
    if len(sys.argv) != 3 or sys.argv[1].startswith("-"):
        fail("usage: python3 tools/plot_accuracy.py ACCURACY_CSV OUT_PNG")
    source, target = sys.argv[1], sys.argv[2]
    rows = read(source)
    sweeps = curves(rows, lambda s: s in ("dt", "nx"))
    precision = curves(rows, lambda s: s == "precision")
    integrators = curves(rows, lambda s: s in INTEGRATORS)

    figure, axes = plt.subplots(3, 3, figsize=(16, 14))
    for (sim, sweep, scalar), points in sorted(sweeps.items()):
        style = dict(color=SIM_COLOURS.get(sim, "black"), marker=SWEEP_MARKERS.get(sweep, "x"),
                     linestyle=SCALAR_STYLES.get(scalar, ":"), markersize=4,
                     label=f"{sim} {sweep}, {scalar}")
        paper = PAPER_H.get((sim, sweep), 1.0)
        for column, key in enumerate(("state_error", "grad_error")):
            keep = [p for p in points if p[key] > 0]
            axes[0][column].loglog([p["ms"] for p in keep], [p[key] for p in keep], **style)
            axes[1][column].loglog([p["h"] / paper for p in keep], [p[key] for p in keep],
                                   **style)
    for column, name in enumerate(("final state", "gradient g_R")):
        axes[0][column].set_xlabel("ms per forward + Full sweep (batch 8, 1 thread)")
        axes[0][column].set_ylabel(f"relative error of the {name}")
        axes[0][column].set_title(f"{name}: error against time")
        axes[1][column].set_xlabel("step / paper's step  (dt, or dx for the nx sweep)")
        axes[1][column].set_ylabel(f"relative error of the {name}")
        axes[1][column].set_title(f"{name}: error against step size")
        # Reference slopes through a point in the middle of the panel.
        low, high = axes[1][column].get_xlim()
        bottom, top = axes[1][column].get_ylim()
        anchor_x = (low * high) ** 0.5
        anchor_y = (bottom * top) ** 0.5
        for slope, dash in ((1, (1, 2)), (2, (4, 2))):
            xs = [low, high]
            ys = [anchor_y * (x / anchor_x) ** slope for x in xs]
            axes[1][column].loglog(xs, ys, color="grey", linewidth=0.8, dashes=dash,
                                   label=f"slope {slope}")
        axes[1][column].set_xlim(low, high)
        axes[1][column].set_ylim(bottom, top)
    for (sim, _, scalar), points in sorted(precision.items()):
        style = dict(color=SIM_COLOURS.get(sim, "black"), marker="^", markersize=4,
                     label=f"{sim}: {scalar} vs double")
        for row_index, key in enumerate(("state_error", "grad_error")):
            keep = [p for p in points if p[key] > 0]
            axes[row_index][2].semilogy([p["h"] for p in keep], [p[key] for p in keep], **style)
    for row_index, name in enumerate(("final state", "gradient g_R")):
        axes[row_index][2].set_xlabel("horizon / paper's horizon")
        axes[row_index][2].set_ylabel(f"relative error of the {name}")
        axes[row_index][2].set_title(f"float against double: {name}")
    paper = [p for (_, sweep, _), points in integrators.items() if sweep == "sie"
             for p in points if abs(p["h"] - 0.01) < 1e-9]
    for (_, sweep, _), points in sorted(integrators.items()):
        name, colour = INTEGRATORS[sweep]
        style = dict(color=colour, marker="o", markersize=4, label=name)
        for column, key in enumerate(("state_error", "grad_error")):
            keep = [p for p in points if p[key] > 0]
            axes[2][column].loglog([p["ms"] for p in keep], [p[key] for p in keep], **style)
        keep = [p for p in points if p["state_error"] > 0]
        axes[2][2].loglog([p["h"] for p in keep], [p["state_error"] for p in keep], **style)
    for column, name in enumerate(("final state", "gradient g_R")):
        key = ("state_error", "grad_error")[column]
        if paper:
            axes[2][column].axhline(paper[0][key], color="grey", linewidth=0.8,
                                    label="paper's accuracy (semi-implicit Euler, h = 0.01)")
        axes[2][column].set_xlabel("ms per forward + Full sweep (batch 8, 1 thread)")
        axes[2][column].set_ylabel(f"relative error of the {name}")
        axes[2][column].set_title(f"cart pole integrators: {name} error against time")
    axes[2][2].set_xlabel("physics step h (control every 0.04)")
    axes[2][2].set_ylabel("relative error of the final state")
    axes[2][2].set_title("cart pole integrators: error against h")
    if integrators:
        low, high = axes[2][2].get_xlim()
        bottom, top = axes[2][2].get_ylim()
        for slope, dash in ((1, (1, 2)), (2, (4, 2)), (4, (6, 2, 1, 2))):
            ys = [top * (x / high) ** slope for x in (low, high)]
            axes[2][2].loglog([low, high], ys, color="grey", linewidth=0.8, dashes=dash,
                              label=f"slope {slope}")
        axes[2][2].set_xlim(low, high)
        axes[2][2].set_ylim(bottom, top)
    for axis in axes.flat:
        axis.grid(True, which="major", alpha=0.3)
        axis.legend(fontsize=7)
    figure.suptitle("sbptt: speed against error (examples/accuracy; reference: double, 16× "
                    "finer step or grid)")
    figure.tight_layout()

    directory = os.path.dirname(os.path.abspath(target))
    handle, temporary = tempfile.mkstemp(suffix=".png", dir=directory)
    os.close(handle)
    try:
        figure.savefig(temporary, dpi=110)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)  # mkstemp creates 0600; a plot is for reading
        os.replace(temporary, target)
    except OSError as error:
        fail(f"cannot write '{target}': {error.strerror}")
    finally:  # also when savefig raises something else than OSError
        if os.path.exists(temporary):
            os.remove(temporary)
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
