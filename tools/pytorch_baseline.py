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
  as lerp(x̄, x, a) = x̄ + a·(x − x̄), x̄ = x detached, a value of x whose gradient the
  backward pass multiplies by the gate a. Two backward passes over the one graph give g_R
  (a = 1) and g_M (a = 0: the gradient stopped at the network's input), a set between them
  through `.data`, which autograd's version check does not see. The update takes g_M where
  its sign agrees with g_R's, 0 elsewhere (sign(0) = 0, as in
  include/sbptt/optim/combined_update.hpp).

The equations are those of include/sbptt/sim/cartpole.hpp and schrodinger.hpp. The numbers
are not meant to match sbptt's bit for bit; the work is. Three untimed calls of each path
come first (TorchScript optimizes its graph after profiling the first calls). `--check`
compares the scripted gradients, after those calls, with plain eager rollouts', quantum
control's step with the complex equation solved directly, and checks that its steps keep
‖ψ‖ = 1.

Needs Debian's python3-torch and OpenBLAS (`apt-get install python3-torch
libopenblas0-pthread`): without OpenBLAS, Debian's torch multiplies with the reference BLAS,
which made the cart pole's R epoch 1.4 times as long (docs/benchmark-runs-zen4.md,
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
os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ["OMP_NUM_THREADS"] = "1"
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
    (I + ihH) ψ' = (I − ihH) ψ, H = H₀ + u·diag(x_j), by a dense batched LU, O(Nx³) where
    sbptt's tridiagonal solve is O(Nx): PyTorch 1.13 has no batched tridiagonal solver."""
    zero_last_kernel = False

    def __init__(self):
        super().__init__()
        self.grid, self.steps, self.continuous = 32, 128, True
        n, dx, self.half_dt = self.grid, 2.0 / (self.grid + 1), 0.0625 / 2
        f64 = torch.float64
        self.h0 = (2 * torch.eye(n, dtype=f64) - torch.diag(torch.ones(n - 1, dtype=f64), 1)
                   - torch.diag(torch.ones(n - 1, dtype=f64), -1)) / (dx * dx)
        self.positions = torch.arange(1, n + 1, dtype=f64) * dx
        # A complex-linear map acts on a (Re, Im) pair as kron(·, [[Re, −Im], [Im, Re]]); i is
        # kron(·, J). U₁ = I + ihH = base + u·field, and U₂ = I − ihH = U₁ᵀ.
        j = torch.tensor([[0.0, -1.0], [1.0, 0.0]], dtype=f64)
        self.register_buffer("base",
                             torch.eye(2 * n, dtype=f64) + torch.kron(self.half_dt * self.h0, j))
        self.register_buffer("field", torch.kron(self.half_dt * torch.diag(self.positions), j))
        self.register_buffer("target", self.eigenstate(3))

    def eigenstate(self, level: int) -> torch.Tensor:
        j = torch.arange(1, self.grid + 1, dtype=torch.float64)
        phi = torch.sin(math.pi * level * j / (self.grid + 1))
        return phi / phi.norm()

    def step(self, state: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        system = torch.addcmul(self.base, u.view(-1, 1, 1), self.field)  # U₁, one per sample
        rhs = torch.bmm(system.transpose(1, 2), state.unsqueeze(2))     # U₂ψ
        return torch.linalg.solve(system, rhs).squeeze(2)

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
                net_input = torch.lerp(state.detach(), state, gate)
            state = self.task.step(state, self.net(net_input))
            if self.continuous:
                total = total + self.task.loss(state)
        return total if self.continuous else self.task.loss(state)


TASKS = {"cartpole": CartPole, "quantum": Quantum}


def weighted_layers(net: torch.nn.Module) -> list:
    return [m for m in net.modules() if isinstance(m, (torch.nn.Linear, torch.nn.Conv1d))]


def setup(task_name: str, dtype: torch.dtype):
    """The task, its network (Glorot weights, zero biases, seed 0) and its 256 training states."""
    task = TASKS[task_name]().to(dtype)
    torch.manual_seed(0)
    net = task.network()
    layers = weighted_layers(net)
    for layer in layers:
        torch.nn.init.xavier_uniform_(layer.weight)
        torch.nn.init.zeros_(layer.bias)
    if task.zero_last_kernel:
        torch.nn.init.zeros_(layers[-1].weight)
    states = task.initial_states(SAMPLES, torch.Generator().manual_seed(42))
    return task, net.to(dtype), states.to(dtype)


def gated_gradients(rollout, batch, gate, params):
    """g_R and g_M of one forward pass through the gate (see the file comment)."""
    # gate.data: set without bumping the version counter that autograd checks against the
    # value it saved in the forward pass.
    gate.data.fill_(1)
    loss = rollout(batch, gate)
    regular = torch.autograd.grad(loss, params, retain_graph=True)
    gate.data.fill_(0)
    return loss, regular, torch.autograd.grad(loss, params)


def warm_up(rollout, batch, gate, ungated, params):
    """TorchScript profiles the first calls and optimizes the graph after them: three calls of
    each path before the checks and the timed epochs, so that both see the optimized graph."""
    for _ in range(3):
        gated_gradients(rollout, batch, gate, params)
        torch.autograd.grad(rollout(batch, ungated), params)


def check(task_name: str) -> bool:
    """Whether the scripted rollout's gradients (g_R ungated, and g_R, g_M through the gate),
    after the warm-up, equal those of plain eager rollouts with the network's input attached
    (g_R) and detached (g_M), in float64, with a random last layer (with the cart pole's
    zeroed one g_R = g_M at the first update); for quantum control also whether the steps
    keep ‖ψ‖ = 1 (Crank–Nicolson is unitary)."""
    dtype = torch.float64
    task, net, states = setup(task_name, dtype)
    torch.nn.init.normal_(weighted_layers(net)[-1].weight, std=0.1)
    params = list(net.parameters())
    batch = states[:BATCH]
    rollout = torch.jit.script(Rollout(task, net))
    gate, ungated = torch.ones((), dtype=dtype), torch.empty(0, dtype=dtype)
    warm_up(rollout, batch, gate, ungated, params)
    _, regular, modified = gated_gradients(rollout, batch, gate, params)
    plain = torch.autograd.grad(rollout(batch, ungated), params)

    def eager(stop: bool):
        state, total = batch, 0
        for _ in range(task.steps):
            state = task.step(state, net(state.detach() if stop else state))
            if task.continuous:
                total = total + task.loss(state)
        return torch.autograd.grad(total if task.continuous else task.loss(state), params)

    def largest(a, b):  # relative to the largest entry of b
        scale = max(y.abs().max().item() for y in b)
        return max((x - y).abs().max().item() for x, y in zip(a, b)) / scale
    eager_regular, eager_modified = eager(False), eager(True)
    errors = (largest(plain, eager_regular), largest(regular, eager_regular),
              largest(modified, eager_modified))
    spread = largest(modified, regular)
    print(f"check {task_name}, relative to the largest entry: ungated g_R against eager "
          f"{errors[0]:.3g}, gated g_R {errors[1]:.3g}, gated g_M {errors[2]:.3g}; "
          f"g_M against g_R {spread:.3g}")
    passed = max(errors) <= 1e-12 and spread > 1e-6
    if task_name == "quantum":
        passed = check_quantum_step(task, net, batch) and passed
    return passed


def check_quantum_step(task, net, batch) -> bool:
    """The real step against the complex equation solved directly, (I + ihH) ψ' = (I − ihH) ψ
    in complex128 with the task's H₀ and x_j, for random fields u; and ‖ψ‖ after a rollout
    (the step is unitary)."""
    u = torch.randn(batch.shape[0], generator=torch.Generator().manual_seed(7),
                    dtype=torch.float64) * 5
    hamiltonian = task.h0 + u.view(-1, 1, 1) * torch.diag(task.positions)
    ihh = 1j * task.half_dt * hamiltonian.to(torch.complex128)
    eye = torch.eye(task.grid, dtype=torch.complex128)
    psi = torch.complex(batch[:, 0::2], batch[:, 1::2]).unsqueeze(2)
    expected = torch.linalg.solve(eye + ihh, (eye - ihh) @ psi).squeeze(2)
    with torch.no_grad():
        stepped = task.step(batch, u.view(-1, 1))
    step_error = (torch.complex(stepped[:, 0::2], stepped[:, 1::2]) - expected).abs().max().item()
    state = batch
    with torch.no_grad():
        for _ in range(task.steps):
            state = task.step(state, net(state))
    drift = (state.norm(dim=1) - 1).abs().max().item()
    print(f"check quantum: one step against the complex solve {step_error:.3g}; "
          f"largest | |psi| - 1 | after {task.steps} steps {drift:.3g}")
    return step_error <= 1e-12 and drift <= 1e-12


def blas_library() -> str:
    """The BLAS and LAPACK that torch's products and solves run in, from this process's mapped
    files: Debian's torch calls libblas.so.3 and liblapack.so.3, whichever implementations
    `update-alternatives` selects (the reference ones or OpenBLAS)."""
    torch.ones(8, 100) @ torch.ones(100, 100)
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps
                     if "blas" in line.lower() or "lapack" in line.lower()}
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
                        help="check the gradients against eager rollouts (and quantum control's "
                        "step against the complex equation), in float64; no timing")
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
    warm_up(rollout, train[:BATCH], gate, ungated, params)
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
                loss, regular, modified = gated_gradients(rollout, batch, gate, params)
                for p, r, m in zip(params, regular, modified):
                    p.grad = torch.where(torch.sign(m) == torch.sign(r), m, torch.zeros_like(m))
            optimizer.step()
        seconds.append(time.perf_counter() - start)
        print(f"epoch {epoch + 1}  last batch's loss {loss.item():.6g}  {seconds[-1]:.3f}s")
    print(f"median {statistics.median(seconds):.3f} s an epoch")
    return 0


if __name__ == "__main__":
    sys.exit(main())
