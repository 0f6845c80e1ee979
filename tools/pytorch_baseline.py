#!/usr/bin/python3
"""The training of examples/cartpole (4 poles) and examples/quantum (--target 2) in PyTorch,
timed: the baseline that docs/benchmarks.md ("Against PyTorch") compares sbptt's epochs with.

What a careful PyTorch user would write for the paper's settings (the cart pole's MLP 10 →
100 → 100 → 1 tanh over 100 steps, the loss at the end; quantum control's CNN over 128
Crank–Nicolson steps of a 32-point grid, the loss summed over the steps; batch 8, Adam lr 1e-3,
256 training samples, so 32 updates an epoch), one thread, and the same work per epoch as the
`seconds` column of sbptt's training log (the updates, no evaluation):

- R: the regular gradient, the rollout under TorchScript (`torch.jit.script`).
- C: the combined update in one forward pass, also scripted: the network reads its input
  as x̄ + a·(x − x̄), x̄ = x detached, a value of x whose gradient the backward pass
  multiplies by the gate a. Two backward passes over the one graph give g_R (a = 1) and g_M
  (a = 0: the gradient stopped at the network's input), a set between them through `.data`,
  which autograd's version check does not see. The update takes g_M where its sign agrees
  with g_R's, 0 elsewhere (sign(0) = 0, as in include/sbptt/optim/combined_update.hpp).

The equations are those of include/sbptt/sim/cartpole.hpp and schrodinger.hpp. The numbers
are not meant to match sbptt's bit for bit; the work is. `--check` compares both gradients
with plain eager rollouts', and checks that quantum control's steps keep ‖ψ‖ = 1.

Needs Debian's python3-torch and OpenBLAS (`apt-get install python3-torch
libopenblas0-pthread`): without OpenBLAS, Debian's torch multiplies with the reference BLAS,
which made the cart pole's R epoch about 1.5 times as long (docs/benchmark-runs-zen4.md,
forty-first run). It prints the BLAS it ran with. Usage:
    /usr/bin/python3 tools/pytorch_baseline.py [--task cartpole|quantum] [--method R|C]
        [--dtype float64|float32] [--epochs N] [--check]
Prints one line per epoch and the median of the epochs' seconds; with `--check` the checks'
figures instead (exit 1 if one fails).
"""
import argparse
import math
import os
import statistics
import sys
import time

# One thread for OpenBLAS too, which torch.set_num_threads does not reach; before the import.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
import torch  # noqa: E402

BATCH, SAMPLES = 8, 256


class CartPole(torch.nn.Module):
    """The paper's cart pole, 4 poles, 100 steps of dt 0.01; loss 1 − mean cos θ_i at the end."""
    zero_last_kernel = True  # the paper's

    def __init__(self):
        super().__init__()
        self.poles, self.steps, self.continuous = 4, 100, False

    def step(self, state: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        # Literals: TorchScript does not read Python globals.
        gravity, pole_mass, total_mass, half_length, dt = 9.8, 0.1, 1.1, 0.5, 0.01
        x, v = state[:, 0:1], state[:, 1:2]
        theta, omega = state[:, 2::2], state[:, 3::2]
        sin, cos = torch.sin(theta), torch.cos(theta)
        a = (force + pole_mass * half_length * omega * omega * sin) / total_mass
        theta_dd = (gravity * sin - cos * a) / (
            half_length * (4.0 / 3.0 - pole_mass * cos * cos / total_mass))
        x_dd = (force + pole_mass * half_length *
                (omega * omega * sin - theta_dd * cos).sum(dim=1, keepdim=True)) / total_mass
        omega_next = omega + dt * theta_dd
        theta_next = theta + dt * omega_next
        v_next = v + dt * x_dd
        x_next = x + dt * v_next
        poles = torch.stack((theta_next, omega_next), dim=2).reshape(state.shape[0], -1)
        return torch.cat((x_next, v_next, poles), dim=1)

    def loss(self, state: torch.Tensor) -> torch.Tensor:
        return (1.0 - torch.cos(state[:, 2::2]).mean(dim=1)).mean()

    def network(self) -> torch.nn.Module:
        return torch.nn.Sequential(
            torch.nn.Linear(2 + 2 * self.poles, 100), torch.nn.Tanh(),
            torch.nn.Linear(100, 100), torch.nn.Tanh(), torch.nn.Linear(100, 1))

    def initial_states(self, count: int, g: torch.Generator) -> torch.Tensor:
        def u(*shape):
            return torch.rand(*shape, generator=g, dtype=torch.float64) * 2 - 1
        states = torch.empty(count, 2 + 2 * self.poles, dtype=torch.float64)
        states[:, 0], states[:, 1] = u(count), u(count)
        states[:, 2::2] = math.pi + u(count, self.poles) * math.pi / 6
        states[:, 3::2] = u(count, self.poles)
        return states


class Quantum(torch.nn.Module):
    """The paper's quantum control, Nx = 32, 128 Crank–Nicolson steps of dt 0.0625 in a well of
    width 2 (include/sbptt/sim/schrodinger.hpp), the state (Re ψ_j, Im ψ_j) interleaved; loss
    Σ_t 1 − |⟨φ_3, ψ_t⟩|² (`quantum --target 2`). A step solves the real 2Nx × 2Nx form of
    (I + ihH) ψ' = (I − ihH) ψ, H = H₀ + u·diag(x_j), by a dense batched solve, as a PyTorch
    user would."""
    zero_last_kernel = False

    def __init__(self):
        super().__init__()
        self.grid, self.steps, self.continuous = 32, 128, True
        n, dx = self.grid, 2.0 / (self.grid + 1)
        h0 = (torch.diag(torch.full((n,), 2.0)) - torch.diag(torch.ones(n - 1), 1)
              - torch.diag(torch.ones(n - 1), -1)) / (dx * dx)
        self.half_dt = 0.0625 / 2
        self.register_buffer("h0", h0.double())
        self.register_buffer("positions", (torch.arange(1, n + 1) * dx).double())
        self.register_buffer("identity", torch.eye(n).double())
        self.register_buffer("target", self.eigenstate(3))

    def eigenstate(self, level: int) -> torch.Tensor:
        j = torch.arange(1, self.grid + 1, dtype=torch.float64)
        phi = torch.sin(math.pi * level * j / (self.grid + 1))
        return phi / phi.norm()

    def step(self, state: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        re, im = state[:, 0::2], state[:, 1::2]
        hh = self.half_dt * (self.h0 + u.view(-1, 1, 1) * torch.diag(self.positions))
        eye = self.identity.expand_as(hh)
        system = torch.cat((torch.cat((eye, -hh), dim=2), torch.cat((hh, eye), dim=2)), dim=1)
        rhs = torch.cat((re + (hh @ im.unsqueeze(2)).squeeze(2),
                         im - (hh @ re.unsqueeze(2)).squeeze(2)), dim=1)
        solution = torch.linalg.solve(system, rhs)
        next_re, next_im = solution[:, :self.grid], solution[:, self.grid:]
        return torch.stack((next_re, next_im), dim=2).reshape(state.shape[0], -1)

    def loss(self, state: torch.Tensor) -> torch.Tensor:
        overlap_re, overlap_im = state[:, 0::2] @ self.target, state[:, 1::2] @ self.target
        return (1.0 - overlap_re * overlap_re - overlap_im * overlap_im).mean()

    def network(self) -> torch.nn.Module:
        return QuantumNetwork(self.grid)

    def initial_states(self, count: int, g: torch.Generator) -> torch.Tensor:
        c = torch.randn(count, 2, generator=g, dtype=torch.float64)
        phase = torch.rand(count, 2, generator=g, dtype=torch.float64) * 2 * math.pi
        c = c / c.norm(dim=1, keepdim=True)
        phi = torch.stack((self.eigenstate(1), self.eigenstate(2)))  # 2 × Nx
        re = (c * torch.cos(phase)) @ phi
        im = (c * torch.sin(phase)) @ phi
        return torch.stack((re, im), dim=2).reshape(count, -1)


class QuantumNetwork(torch.nn.Module):
    """The paper's CNN: conv 2→60 k3 s2 tanh, conv 60→60 k3 s2 tanh, dense 420→1."""
    def __init__(self, grid: int):
        super().__init__()
        self.grid = grid
        self.convolutions = torch.nn.Sequential(
            torch.nn.Conv1d(2, 60, 3, stride=2), torch.nn.Tanh(),
            torch.nn.Conv1d(60, 60, 3, stride=2), torch.nn.Tanh())
        positions = ((grid - 3) // 2 + 1 - 3) // 2 + 1  # after the two convolutions: 7
        self.dense = torch.nn.Linear(60 * positions, 1)

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        channels = state.view(state.shape[0], self.grid, 2).transpose(1, 2)
        return self.dense(self.convolutions(channels).flatten(1))


class Rollout(torch.nn.Module):
    def __init__(self, task: torch.nn.Module, net: torch.nn.Module):
        super().__init__()
        self.task = task
        self.net = net
        self.steps = task.steps
        self.continuous = task.continuous

    def forward(self, state: torch.Tensor, gate: torch.Tensor) -> torch.Tensor:
        """The loss of a rollout from `state`; with `gate` (a 0-d tensor, 1 forward) the
        network's input is gated: the backward pass multiplies its gradient by gate's value
        at that time."""
        total = torch.zeros((), dtype=state.dtype)
        for _ in range(self.steps):
            net_input = state
            if gate.numel() > 0:
                fixed = state.detach()
                net_input = fixed + gate * (state - fixed)
            state = self.task.step(state, self.net(net_input))
            if self.continuous:
                total = total + self.task.loss(state)
        return total if self.continuous else self.task.loss(state)


TASKS = {"cartpole": CartPole, "quantum": Quantum}


def setup(task_name: str, dtype: torch.dtype):
    """The task, its network (Glorot weights, zero biases, seed 0) and its 256 training states."""
    task = TASKS[task_name]().to(dtype)
    torch.manual_seed(0)
    net = task.network()
    layers = [m for m in net.modules() if isinstance(m, (torch.nn.Linear, torch.nn.Conv1d))]
    for layer in layers:
        torch.nn.init.xavier_uniform_(layer.weight)
        torch.nn.init.zeros_(layer.bias)
    if task.zero_last_kernel:
        torch.nn.init.zeros_(layers[-1].weight)
    states = task.initial_states(SAMPLES, torch.Generator().manual_seed(42))
    return task, net.to(dtype), states.to(dtype)

def check(task_name: str) -> bool:
    """Whether the gated rollout's two gradients equal those of plain eager rollouts, with the
    network's input attached (g_R) and detached (g_M), in float64, with a random last layer
    (with the cart pole's zeroed one g_R = g_M at the first update); for quantum control also
    whether the steps keep ‖ψ‖ = 1 (Crank–Nicolson is unitary)."""
    task, net, states = setup(task_name, torch.float64)
    layers = [m for m in net.modules() if isinstance(m, (torch.nn.Linear, torch.nn.Conv1d))]
    torch.nn.init.normal_(layers[-1].weight, std=0.1)
    params = list(net.parameters())
    batch = states[:BATCH]
    gate = torch.ones((), dtype=torch.float64)
    loss = torch.jit.script(Rollout(task, net))(batch, gate)
    regular = torch.autograd.grad(loss, params, retain_graph=True)
    gate.data.fill_(0)
    modified = torch.autograd.grad(loss, params)

    def eager(stop: bool):
        state, total = batch, 0
        for _ in range(task.steps):
            state = task.step(state, net(state.detach() if stop else state))
            if task.continuous:
                total = total + task.loss(state)
        return torch.autograd.grad(total if task.continuous else task.loss(state), params)

    def largest(a, b):
        return max((x - y).abs().max().item() for x, y in zip(a, b))
    errors = (largest(regular, eager(False)), largest(modified, eager(True)))
    spread = largest(regular, modified)
    print(f"check {task_name}: |g_R - eager g_R| = {errors[0]:.3g}, "
          f"|g_M - eager g_M| = {errors[1]:.3g}, |g_R - g_M| = {spread:.3g}")
    passed = max(errors) <= 1e-12 and spread > 0
    if task_name == "quantum":
        state = batch
        with torch.no_grad():
            for _ in range(task.steps):
                state = task.step(state, net(state))
        drift = (state.norm(dim=1) - 1).abs().max().item()
        print(f"check quantum: largest | |psi| - 1 | after {task.steps} steps = {drift:.3g}")
        passed = passed and drift <= 1e-12
    return passed


def blas_library() -> str:
    """The BLAS that torch's products ran in, from this process's mapped files: Debian's torch
    calls libblas.so.3, whichever implementation `update-alternatives` selects (the reference
    BLAS, several times slower for these shapes, or OpenBLAS)."""
    torch.ones(8, 100) @ torch.ones(100, 100)
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "blas" in line.lower()}
    except OSError:
        return "unknown"
    return ", ".join(sorted(os.path.realpath(p) for p in paths)) or "none mapped"


def cpu_capability() -> str:
    """The instruction set torch's own kernels run, as its build configuration reports it."""
    lines = [line.strip(" -") for line in torch.__config__.show().splitlines()
             if "CPU capability" in line]
    return lines[0] if lines else "CPU capability not reported"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--task", choices=tuple(TASKS), default="cartpole")
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
        return 0 if check(args.task) else 1
    dtype = getattr(torch, args.dtype)
    task, net, train = setup(args.task, dtype)
    params = list(net.parameters())
    optimizer = torch.optim.Adam(params, lr=1e-3)
    rollout = torch.jit.script(Rollout(task, net))
    ungated = torch.empty(0, dtype=dtype)
    gate = torch.ones((), dtype=dtype)
    print(f"pytorch {torch.__version__}, {torch.get_num_threads()} thread, {args.dtype}, "
          f"{args.task}, method {args.method}, {SAMPLES // BATCH} updates an epoch")
    print(f"blas: {blas_library()}; {cpu_capability()}")
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
