#!/usr/bin/env python3
"""Why does the stopped update (S) train the cart pole at all? A probe for docs/results.md.

    python3 tools/probe_stopped.py [--bin build/examples/cartpole] [--poles 2] [--out DIR]

Trains S at the paper's setting (256 samples, batch 8, NORM clipping, float, seed 42: the run
of the full sweep) for 1, 10, 30, 100, 300 and 1000 epochs, and at each of those parameters
(and the initial ones) dumps the R/M/C/S/N vectors on the 256 training states as one batch
(`--dump-gradients`). It prints, per checkpoint, the batch loss, cos(g_S, g_R), the norms of
g_S and g_R, and how many components of g_S exceed Adam's ε = 1e-7 (below ε, the Keras form
of Adam takes a step of about lr·|g|/ε instead of lr). Each checkpoint is a separate run from
the start; training is deterministic, so it lies on the sweep's trajectory.
"""
import argparse
import csv
import math
import os
import subprocess

EPSILON = 1e-7
CHECKPOINTS = [0, 1, 10, 30, 100, 300, 1000]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bin", default="build/examples/cartpole")
    parser.add_argument("--poles", type=int, default=2)
    parser.add_argument("--out", default="out/probe-stopped")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    common = [args.bin, "--poles", str(args.poles), "--float", "--samples", "256", "--seed", "42"]
    print("| epochs of S | batch loss | cos(g_S, g_R) | ‖g_S‖ | ‖g_R‖ | components of g_S above ε |")
    print("|---:|---:|---:|---:|---:|---:|")
    for epochs in CHECKPOINTS:
        stem = os.path.join(args.out, f"p{args.poles}_e{epochs}")
        init = []
        if epochs > 0:
            subprocess.run(common + ["--method", "S", "--clip", "norm", "--epochs", str(epochs),
                                     "--save-params", stem + ".params"],
                           check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            init = ["--init-params", stem + ".params"]
        dumped = subprocess.run(common + init + ["--dump-gradients", stem + ".csv"], check=True,
                                capture_output=True, text=True).stdout
        loss = float(dumped.split("loss=")[1].split()[0])
        with open(stem + ".csv", newline="") as f:
            rows = list(csv.DictReader(f))
        g_r = [float(r["R"]) for r in rows]
        g_s = [float(r["S"]) for r in rows]
        norm_r = math.sqrt(sum(x * x for x in g_r))
        norm_s = math.sqrt(sum(x * x for x in g_s))
        cosine = sum(a * b for a, b in zip(g_s, g_r)) / (norm_r * norm_s) if norm_s > 0 else 0.0
        above = sum(1 for x in g_s if abs(x) > EPSILON)
        print(f"| {epochs} | {loss:.4g} | {cosine:.3f} | {norm_s:.3g} | {norm_r:.3g} | "
              f"{above} of {len(g_s)} |")


if __name__ == "__main__":
    main()
