#!/usr/bin/python3
"""The cart-pole training of examples/cartpole in PyTorch, timed: the baseline that
docs/benchmarks.md ("Against PyTorch") compares sbptt's epochs with.

What a careful PyTorch user would write for the paper's setting (4 poles, MLP 10 → 100 → 100
→ 1 tanh, batch 8, 100 steps of dt 0.01, the loss 1 − mean cos θ_i of the final state, Adam
lr 1e-3, 256 training samples, so 32 updates an epoch), one thread, and the same work per
epoch as the `seconds` column of sbptt's training log (the updates, no evaluation):

- R: the regular gradient, the rollout under TorchScript (`torch.jit.script`).
- C: the combined update in one forward pass, also scripted: the network reads its input
  as x̄ + a·(x − x̄), x̄ = x detached, a value of x whose gradient the backward pass
  multiplies by the gate a. Two backward passes over the one graph give g_R (a = 1) and g_M
  (a = 0: the gradient stopped at the network's input), a set between them through `.data`,
  which autograd's version check does not see; `--check` shows that both equal plain eager
  rollouts'. The update takes g_M where its sign agrees with g_R's, 0 elsewhere (sign(0) = 0,
  as in include/sbptt/optim/combined_update.hpp).

The equations are those of include/sbptt/sim/cartpole.hpp (the paper's decoupled poles,
semi-implicit Euler). The numbers are not meant to match sbptt's bit for bit; the work is.

Needs Debian's python3-torch (`apt-get install python3-torch`). Usage:
    /usr/bin/python3 tools/pytorch_baseline.py [--method R|C] [--dtype float64|float32]
        [--epochs N] [--check]
Prints one line per epoch and the median of the epochs' seconds. `--check` compares C's two
gradients with plain eager rollouts instead (exit 1 if they differ).
"""
import argparse
import math
import statistics
import sys
import time

import torch

POLES, STEPS = 4, 100
BATCH, SAMPLES = 8, 256


def step(state: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
    """One step of the paper's cart pole for a batch: state is batch × (2 + 2P)."""
    # Literals: TorchScript does not read Python globals.
    GRAVITY, POLE_MASS, TOTAL_MASS, HALF_LENGTH, DT = 9.8, 0.1, 1.1, 0.5, 0.01
    x, v = state[:, 0:1], state[:, 1:2]
    theta, omega = state[:, 2::2], state[:, 3::2]
    sin, cos = torch.sin(theta), torch.cos(theta)
    a = (force + POLE_MASS * HALF_LENGTH * omega * omega * sin) / TOTAL_MASS
    theta_dd = (GRAVITY * sin - cos * a) / (
        HALF_LENGTH * (4.0 / 3.0 - POLE_MASS * cos * cos / TOTAL_MASS))
    x_dd = (force + POLE_MASS * HALF_LENGTH *
            (omega * omega * sin - theta_dd * cos).sum(dim=1, keepdim=True)) / TOTAL_MASS
    omega_next = omega + DT * theta_dd
    theta_next = theta + DT * omega_next
    v_next = v + DT * x_dd
    x_next = x + DT * v_next
    poles = torch.stack((theta_next, omega_next), dim=2).reshape(state.shape[0], -1)
    return torch.cat((x_next, v_next, poles), dim=1)


def final_loss(state: torch.Tensor) -> torch.Tensor:
    return (1.0 - torch.cos(state[:, 2::2]).mean(dim=1)).mean()


class Rollout(torch.nn.Module):
    def __init__(self, net: torch.nn.Module):
        super().__init__()
        self.net = net
        self.steps = STEPS

    def forward(self, state: torch.Tensor, gate: torch.Tensor) -> torch.Tensor:
        """The loss of a rollout from `state`; with `gate` (a 0-d tensor, 1 forward) the
        network's input is gated: the backward pass multiplies its gradient by gate's value
        at that time."""
        for _ in range(self.steps):
            net_input = state
            if gate.numel() > 0:
                fixed = state.detach()
                net_input = fixed + gate * (state - fixed)
            state = step(state, self.net(net_input))
        return final_loss(state)


def network(dtype: torch.dtype) -> torch.nn.Module:
    torch.manual_seed(0)
    net = torch.nn.Sequential(
        torch.nn.Linear(2 + 2 * POLES, 100), torch.nn.Tanh(),
        torch.nn.Linear(100, 100), torch.nn.Tanh(), torch.nn.Linear(100, 1))
    for layer in net:
        if isinstance(layer, torch.nn.Linear):
            torch.nn.init.xavier_uniform_(layer.weight)
            torch.nn.init.zeros_(layer.bias)
    torch.nn.init.zeros_(net[-1].weight)  # the paper's zeroed last kernel
    return net.to(dtype)


def initial_states(count: int, dtype: torch.dtype) -> torch.Tensor:
    g = torch.Generator().manual_seed(42)
    u = lambda *shape: torch.rand(*shape, generator=g, dtype=torch.float64) * 2 - 1
    states = torch.empty(count, 2 + 2 * POLES, dtype=torch.float64)
    states[:, 0], states[:, 1] = u(count), u(count)
    states[:, 2::2] = math.pi + u(count, POLES) * math.pi / 6
    states[:, 3::2] = u(count, POLES)
    return states.to(dtype)


def check(dtype: torch.dtype) -> bool:
    """Whether the gated rollout's two gradients equal those of plain eager rollouts, with the
    network's input attached (g_R) and detached (g_M), for a network with a nonzero last
    kernel (with the paper's zeroed one g_R = g_M at the first update)."""
    net = network(dtype)
    torch.nn.init.normal_(net[-1].weight, std=0.1)
    params = list(net.parameters())
    batch = initial_states(BATCH, dtype)
    gate = torch.ones((), dtype=dtype)
    loss = torch.jit.script(Rollout(net))(batch, gate)
    regular = torch.autograd.grad(loss, params, retain_graph=True)
    gate.data.fill_(0)
    modified = torch.autograd.grad(loss, params)

    def eager(stop: bool):
        state = batch
        for _ in range(STEPS):
            state = step(state, net(state.detach() if stop else state))
        return torch.autograd.grad(final_loss(state), params)

    def largest(a, b):
        return max((x - y).abs().max().item() for x, y in zip(a, b))
    errors = (largest(regular, eager(False)), largest(modified, eager(True)))
    print(f"check: |g_R - eager g_R| = {errors[0]:.3g}, |g_M - eager g_M| = {errors[1]:.3g}, "
          f"|g_R - g_M| = {largest(regular, modified):.3g}")
    return max(errors) <= 1e-12 and largest(regular, modified) > 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--method", choices=("R", "C"), default="R")
    parser.add_argument("--dtype", choices=("float64", "float32"), default="float64")
    parser.add_argument("--epochs", type=int, default=5)
    parser.add_argument("--check", action="store_true",
                        help="compare C's two gradients with eager rollouts (float64), no timing")
    args = parser.parse_args()
    if args.epochs < 1:
        parser.error(f"--epochs {args.epochs}: expected at least 1")
    torch.set_num_threads(1)
    if args.check:
        return 0 if check(torch.float64) else 1
    dtype = getattr(torch, args.dtype)
    net = network(dtype)
    params = list(net.parameters())
    optimizer = torch.optim.Adam(params, lr=1e-3)
    train = initial_states(SAMPLES, dtype)
    rollout = torch.jit.script(Rollout(net))
    ungated = torch.empty(0, dtype=dtype)
    gate = torch.ones((), dtype=dtype)
    print(f"pytorch {torch.__version__}, {torch.get_num_threads()} thread, {args.dtype}, "
          f"method {args.method}, cart pole {POLES} poles, {SAMPLES // BATCH} updates an epoch")
    seconds = []
    for epoch in range(args.epochs):
        order = torch.randperm(SAMPLES, generator=torch.Generator().manual_seed(epoch))
        start = time.perf_counter()
        for first in range(0, SAMPLES, BATCH):
            batch = train[order[first:first + BATCH]]
            optimizer.zero_grad(set_to_none=True)
            if args.method == "R":
                loss = rollout(batch, ungated)
                loss.backward()
            else:
                # gate.data: set without bumping the version counter that autograd checks
                # against the value it saved in the forward pass.
                gate.data.fill_(1)
                loss = rollout(batch, gate)
                regular = torch.autograd.grad(loss, params, retain_graph=True)
                gate.data.fill_(0)
                modified = torch.autograd.grad(loss, params)
                for p, r, m in zip(params, regular, modified):
                    p.grad = torch.where(torch.sign(m) == torch.sign(r), m, torch.zeros_like(m))
            optimizer.step()
        seconds.append(time.perf_counter() - start)
        print(f"epoch {epoch + 1}  batch loss {loss.item():.6g}  {seconds[-1]:.3f}s")
    print(f"median {statistics.median(seconds):.3f} s an epoch")
    return 0


if __name__ == "__main__":
    sys.exit(main())
