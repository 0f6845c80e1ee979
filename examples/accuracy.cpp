// Speed against error: how the rollout and its gradient converge as the time step (and, for
// quantum control, the grid) is refined, and what float costs in accuracy.
//
// For each simulator (cart pole with 4 poles, guidance 2-4, quantum control Nx = 32) and a
// fixed, seeded controller (Glorot MLP 2×100 tanh / the paper's CNN, last layer NOT zeroed so
// that the control acts), the horizon T is fixed and the number of steps m is swept. Each
// coarse result (final state x_m of a batch of 8, and the regular gradient g_R) is compared
// with a reference in double that takes 16 times finer physics steps.
//
// The comparison has to be between two discretisations of the SAME problem. The controller
// acts at the coarse steps: the reference evaluates the network only at the start of every
// coarse interval and holds its output for the 16 fine steps (zero-order hold), and scores the
// loss at the same coarse times. So the reference differs from the coarse run only by the
// integrator's error, and the error shrinks like dt^p with the integrator's order p
// (semi-implicit / explicit Euler: 1, Crank–Nicolson: 2). (Evaluating the network at every
// fine step instead would change the controlled problem itself with the step, and the
// difference would mix the integrator's error with a control-rate effect.)
//
// The quantum grid sweep keeps dt and refines Nx = 33·r − 1 (r = 1, 2, 4, 8) against a
// reference at r = 16, so that the coarse grid points are grid points of every finer grid. The
// CNN sees the 32 points of the coarsest grid, scaled by √r (the discrete normalisation
// Σ|ψ_j|² = 1 shrinks ψ_j like 1/√r), so that one θ serves every grid; states are compared at
// those 32 points, scaled the same way. The error shrinks like dx² (3-point Laplacian).
//
// Errors are relative: ‖x_m − x_m,ref‖_F / ‖x_m,ref‖_F over the batch, ‖g − g_ref‖ / ‖g_ref‖.
// Milliseconds are one forward pass plus one Full sweep of the batch (1 thread, best of 3).
// Finally, float against double at the paper's settings: the relative error of the final
// state and of g_R for horizons of m/4, m/2, 3m/4 and m steps.
//
// Integrator axis (cart pole, 4 poles): which of the reference's semi-implicit Euler, Heun (RK2)
// and RK4 reaches a given error cheapest. All three solve the same controlled problem: the
// network acts every T/25 = 0.04 (zero-order hold) and the physics takes s = 1 … 64 substeps of
// the integrator in between (h = 0.04/s). The paper's step h = 0.01 is s = 4 of semi-implicit
// Euler; its error is "the paper's accuracy". The reference is RK4 with 1024 substeps. All three
// run through `Integrated` with automatic f-Jacobians over the cart pole's equations
// (examples/common/cartpole_equations.hpp), so their milliseconds compare like with like.
//
// Usage: accuracy [--csv FILE]    (plot: python3 tools/plot_accuracy.py FILE PNG)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <sbptt/sbptt.hpp>

#include "cartpole_equations.hpp"
#include "command_line.hpp"
#include "standard_streams.hpp"

namespace {

using sbptt::Index;
using sbptt::Matrix;
using sbptt::Network;
using sbptt::Vector;

constexpr Index kBatch = 8;
constexpr Index kRefine = 16;

/// A coarse step of `Fine` made of `substeps` fine steps with the control held constant (the
/// reference of the file comment). Its VJP runs back through the substeps.
template <class Fine>
class HeldControl {
public:
  using Scalar = typename Fine::Scalar;
  using State = typename Fine::State;
  using Control = typename Fine::Control;
  using StateJacobian = Matrix<Scalar>;
  using ControlJacobian = Matrix<Scalar>;

  HeldControl(Fine fine, Index substeps) : fine_(std::move(fine)), substeps_(substeps) {}

  [[nodiscard]] Index state_dim() const { return fine_.state_dim(); }
  [[nodiscard]] Index control_dim() const { return fine_.control_dim(); }
  [[nodiscard]] Scalar dt() const { return fine_.dt() * static_cast<Scalar>(substeps_); }

  void step(const State& x, const Control& u, State& x_next) const {
    State current = x;
    for (Index k = 0; k < substeps_; ++k) {
      fine_.step(current, u, x_next);
      current = x_next;
    }
  }

  void jacobians(const State& x, const Control& u, StateJacobian& a, ControlJacobian& b) const {
    typename Fine::StateJacobian fa;
    typename Fine::ControlJacobian fb;
    a = StateJacobian::Identity(state_dim(), state_dim());
    b = ControlJacobian::Zero(state_dim(), control_dim());
    State current = x, next = x;
    for (Index k = 0; k < substeps_; ++k) {
      fine_.jacobians(current, u, fa, fb);
      a = Matrix<Scalar>(fa) * a;
      b = Matrix<Scalar>(fa) * b + Matrix<Scalar>(fb);
      fine_.step(current, u, next);
      current = next;
    }
  }

  void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
           Control* lambda_u) const {
    std::vector<State> states(static_cast<std::size_t>(substeps_), x);
    for (Index k = 1; k < substeps_; ++k)
      fine_.step(states[static_cast<std::size_t>(k - 1)], u, states[static_cast<std::size_t>(k)]);
    State adjoint = lambda, previous = lambda;
    Control total = Control::Zero(control_dim()), part = total;
    for (Index k = substeps_ - 1; k >= 0; --k) {
      fine_.vjp(states[static_cast<std::size_t>(k)], u, adjoint, &previous, &part);
      total += part;
      adjoint = previous;
    }
    if (lambda_x != nullptr) *lambda_x = adjoint;
    if (lambda_u != nullptr) *lambda_u = total;
  }

private:
  Fine fine_;
  Index substeps_;
};

/// The CNN of the 32-point grid applied to a grid with Nx = 33·r − 1 points: it reads every
/// r-th point (the points of the coarsest grid), scaled by √r (see the file comment).
template <class S>
class GridAdapter {
public:
  using Scalar = S;
  struct Workspace {
    typename Network<S>::Workspace inner;
    Matrix<S> input;
  };

  GridAdapter(Network<S>& net, Index ratio) : net_(net), ratio_(ratio) {}

  [[nodiscard]] Index input_dim() const { return 2 * (33 * ratio_ - 1); }
  [[nodiscard]] Index output_dim() const { return net_.output_dim(); }
  [[nodiscard]] Index num_params() const { return net_.num_params(); }
  [[nodiscard]] const Vector<S>& params() const { return net_.params(); }
  [[nodiscard]] Vector<S>& params() { return net_.params(); }

  /// Packs like the network it wraps, so that the engine times the products it would use.
  using PackedWeights = typename Network<S>::PackedWeights;
  void pack(PackedWeights& packed) const { net_.pack(packed); }

  void forward(const Matrix<S>& x, Matrix<S>& y, Workspace& ws) const { forward_with(x, y, ws); }
  void forward(const Matrix<S>& x, Matrix<S>& y, Workspace& ws,
               const PackedWeights& packed) const {
    forward_with(x, y, ws, packed);
  }
  void backward(const Workspace& ws, const Matrix<S>& dy, Vector<S>& grad, Matrix<S>* dx) const {
    backward_with(ws, dy, grad, dx);
  }
  void backward(const Workspace& ws, const Matrix<S>& dy, Vector<S>& grad, Matrix<S>* dx,
                const PackedWeights& packed) const {
    backward_with(ws, dy, grad, dx, packed);
  }

  /// First row of coarse point i (0-based) in the fine state: fine point r·(i+1) − 1.
  [[nodiscard]] Index row(Index i) const { return 2 * (ratio_ * (i + 1) - 1); }

private:
  void forward_with(const Matrix<S>& x, Matrix<S>& y, Workspace& ws,
                    const auto&... packed) const {
    ws.input.resize(64, x.cols());
    const S scale = std::sqrt(static_cast<S>(ratio_));
    for (Index i = 0; i < 32; ++i) ws.input.middleRows(2 * i, 2) = scale * x.middleRows(row(i), 2);
    net_.forward(ws.input, y, ws.inner, packed...);
  }

  void backward_with(const Workspace& ws, const Matrix<S>& dy, Vector<S>& grad, Matrix<S>* dx,
                     const auto&... packed) const {
    Matrix<S> sub;
    net_.backward(ws.inner, dy, grad, dx != nullptr ? &sub : nullptr, packed...);
    if (dx == nullptr) return;
    const S scale = std::sqrt(static_cast<S>(ratio_));
    dx->setZero(input_dim(), dy.cols());
    for (Index i = 0; i < 32; ++i) dx->middleRows(row(i), 2) = scale * sub.middleRows(2 * i, 2);
  }

  Network<S>& net_;
  Index ratio_;
};
static_assert(sbptt::PackingController<GridAdapter<double>>);

/// What one run of an engine gives: final states (state_dim × B), g_R, loss, milliseconds.
struct Outcome {
  Matrix<double> final_states;
  Vector<double> gradient;
  double loss = 0;
  double ms = 0;
};

template <class Sim, class Ctrl, class Objective>
Outcome run_engine(const Sim& sim, const Ctrl& controller, const Objective& objective,
                   Index steps, const Matrix<typename Sim::Scalar>& x0, bool timed) {
  using S = typename Sim::Scalar;
  sbptt::Engine engine(sim, controller, objective, steps);
  Vector<S> g;
  Outcome out;
  double best = 1e300;
  for (int repeat = 0; repeat < (timed ? 3 : 1); ++repeat) {
    const auto start = std::chrono::steady_clock::now();
    out.loss = static_cast<double>(engine.forward(x0));
    engine.reverse(sbptt::FlowMode::Full, g);
    best = std::min(best, std::chrono::duration<double, std::milli>(
                              std::chrono::steady_clock::now() - start)
                              .count());
  }
  out.ms = best;
  out.final_states = engine.trajectory().states.back().template cast<double>();
  out.gradient = g.template cast<double>();
  return out;
}

double relative(const auto& value, const auto& reference) {
  return (value - reference).norm() / reference.norm();
}

struct Point {
  std::string sim, sweep, scalar;
  Index steps = 0, nx = 0;
  double h = 0, ms = 0, state_error = 0, grad_error = 0, loss_error = 0;
};

std::vector<Point> points;

void report(const Point& p) {
  std::printf("%-9s %-9s %-6s %6lld %5lld %10.5g %9.3f %11.3e %11.3e %11.3e\n", p.sim.c_str(),
              p.sweep.c_str(), p.scalar.c_str(), static_cast<long long>(p.steps),
              static_cast<long long>(p.nx), p.h, p.ms, p.state_error, p.grad_error,
              p.loss_error);
  std::fflush(stdout);
  points.push_back(p);
}

/// Observed order of one curve: the least-squares slope of log(error) against log(h) over its
/// `count` finest points (the coarse end of a sweep can lie outside the asymptotic regime).
double order(const std::string& sim, const std::string& sweep, const std::string& scalar,
             bool gradient, std::size_t count) {
  std::vector<std::pair<double, double>> curve;  // (log h, log error), finest first
  for (const auto& p : points) {
    const double e = gradient ? p.grad_error : p.state_error;
    if (p.sim == sim && p.sweep == sweep && p.scalar == scalar && e > 0)
      curve.emplace_back(std::log(p.h), std::log(e));
  }
  std::sort(curve.begin(), curve.end());
  curve.resize(std::min(curve.size(), count));
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const auto& [x, y] : curve) {
    n += 1;
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  return n >= 2 ? (n * sxy - sx * sy) / (n * sxx - sx * sx) : std::nan("");
}

/// Time-step sweep of one simulator family. `make(steps)` gives the simulator of scalar S with
/// m = steps over the fixed horizon; `objective_of(sim)` its objective.
template <class S, class Make, class MakeObjective>
void sweep_steps(const std::string& name, const std::vector<Index>& steps_list, Make make,
                 MakeObjective objective_of, const Network<double>& net_d,
                 const Matrix<double>& x0_d, double horizon) {
  for (const Index m : steps_list) {
    const auto coarse_d = make(double{}, m);
    const HeldControl reference_sim(make(double{}, kRefine * m), kRefine);
    const Outcome ref = run_engine(reference_sim, net_d, objective_of(coarse_d), m, x0_d, false);
    const auto coarse = make(S{}, m);
    Network<S> net(net_d.layers());
    net.params() = net_d.params().template cast<S>();
    const Matrix<S> x0 = x0_d.template cast<S>();
    const Outcome out = run_engine(coarse, net, objective_of(coarse), m, x0, true);
    report({name, "dt", std::is_same_v<S, float> ? "float" : "double", m, 0,
            horizon / static_cast<double>(m), out.ms, relative(out.final_states, ref.final_states),
            relative(out.gradient, ref.gradient), std::abs(out.loss - ref.loss) / std::abs(ref.loss)});
  }
}

/// The integrator axis of the file comment: sweep `label` of `Method` against `reference`.
template <class Method>
void sweep_integrator(const std::string& label, const Network<double>& net,
                      const Matrix<double>& x0, const Outcome& reference) {
  constexpr Index kControlSteps = 25;
  for (const Index substeps : {1, 2, 4, 8, 16, 32, 64}) {
    const double h = 0.04 / static_cast<double>(substeps);
    const HeldControl sim(
        sbptt::Integrated<sbptt::examples::CartPoleEquations<4>, Method>({}, h), substeps);
    const Outcome out = run_engine(sim, net, sbptt::cartpole_objective<double, 4>(),
                                   kControlSteps, x0, true);
    report({"cartpole", label, "double", kControlSteps * substeps, 0, h, out.ms,
            relative(out.final_states, reference.final_states),
            relative(out.gradient, reference.gradient),
            std::abs(out.loss - reference.loss) / std::abs(reference.loss)});
  }
}

/// The integrator axis for the cart pole with 4 poles, and which integrator reaches the paper's
/// accuracy (semi-implicit Euler at h = 0.01) cheapest.
void integrator_axis(const Network<double>& net, const Matrix<double>& x0) {
  using Equations = sbptt::examples::CartPoleEquations<4>;
  const Index substeps = 1024;
  const HeldControl reference_sim(
      sbptt::Integrated<Equations, sbptt::RungeKutta4>({}, 0.04 / static_cast<double>(substeps)),
      substeps);
  const Outcome reference =
      run_engine(reference_sim, net, sbptt::cartpole_objective<double, 4>(), 25, x0, false);
  sweep_integrator<sbptt::SemiImplicitEuler>("sie", net, x0, reference);
  sweep_integrator<sbptt::Heun>("rk2", net, x0, reference);
  sweep_integrator<sbptt::RungeKutta4>("rk4", net, x0, reference);
  const Point* paper = nullptr;
  for (const auto& p : points)
    if (p.sweep == "sie" && std::abs(p.h - 0.01) < 1e-12) paper = &p;
  if (paper == nullptr) return;
  std::printf("\nintegrators, cart pole 4 poles, control every 0.04: the paper's accuracy "
              "(semi-implicit Euler, h = 0.01) is state %.3e, g_R %.3e at %.3f ms\n",
              paper->state_error, paper->grad_error, paper->ms);
  for (const char* label : {"sie", "rk2", "rk4"}) {
    const Point* cheapest = nullptr;
    for (const auto& p : points)
      if (p.sweep == label && p.state_error <= paper->state_error &&
          p.grad_error <= paper->grad_error && (cheapest == nullptr || p.ms < cheapest->ms))
        cheapest = &p;
    if (cheapest != nullptr)
      std::printf("  %s reaches it at h = %.5g (%lld steps): %.3f ms (state %.3e, g_R %.3e)\n",
                  label, cheapest->h, static_cast<long long>(cheapest->steps), cheapest->ms,
                  cheapest->state_error, cheapest->grad_error);
  }
}

sbptt::CartPole<double, 4> cartpole_d(Index m) {
  sbptt::CartPoleOptions o;
  o.steps = m;
  return sbptt::CartPole<double, 4>(o);
}

template <class S>
Network<S> mlp(Index inputs, Index outputs) {
  auto net = Network<S>::mlp(inputs, {100, 100}, outputs);
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);
  return net;
}

Network<double> cnn() {
  Network<double> net({sbptt::Conv1d{32, 2, 60, 3, 2, sbptt::Activation::Tanh},
                       sbptt::Conv1d{15, 60, 60, 3, 2, sbptt::Activation::Tanh},
                       sbptt::Dense{420, 1}});
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);
  return net;
}

template <class S>
using Quantum = sbptt::Schrodinger1D<S, Eigen::Dynamic>;

template <class S>
Quantum<S> quantum(Index nx, Index steps) {
  sbptt::SchrodingerOptions<S> o;
  o.steps = steps;
  o.dt = static_cast<S>(8.0 / static_cast<double>(steps));
  return Quantum<S>(nx, o);
}

/// Quantum grid sweep: dt fixed at the paper's, Nx = 33 r − 1 against r = 16.
template <class S>
void sweep_grid(const Network<double>& net_d) {
  const Index m = 128;
  Network<double> ref_net = net_d;
  const Index ref_ratio = 16;
  const auto ref_sim = quantum<double>(33 * ref_ratio - 1, m);
  sbptt::Rng rng(7);
  const Matrix<double> ref_x0 = ref_sim.initial_states(rng, kBatch);
  const GridAdapter<double> ref_ctrl(ref_net, ref_ratio);
  const Outcome ref = run_engine(ref_sim, ref_ctrl, sbptt::quantum_objective(ref_sim, 4), m,
                                 ref_x0, false);
  for (const Index r : {1, 2, 4, 8}) {
    const auto sim = quantum<S>(33 * r - 1, m);
    sbptt::Rng same(7);  // the same draws: the same continuum initial states
    const Matrix<S> x0 = sim.initial_states(same, kBatch);
    Network<S> net(net_d.layers());
    net.params() = net_d.params().template cast<S>();
    const GridAdapter<S> ctrl(net, r);
    const Outcome out = run_engine(sim, ctrl, sbptt::quantum_objective(sim, 4), m, x0, true);
    // Compare at the 32 shared points, in the grid-independent scaling √r ψ.
    Matrix<double> a(64, kBatch), b(64, kBatch);
    for (Index i = 0; i < 32; ++i) {
      a.middleRows(2 * i, 2) = std::sqrt(double(r)) * out.final_states.middleRows(ctrl.row(i), 2);
      b.middleRows(2 * i, 2) =
          std::sqrt(double(ref_ratio)) * ref.final_states.middleRows(ref_ctrl.row(i), 2);
    }
    report({"quantum", "nx", std::is_same_v<S, float> ? "float" : "double", m, 33 * r - 1,
            2.0 / static_cast<double>(33 * r), out.ms, relative(a, b),
            relative(out.gradient, ref.gradient), std::abs(out.loss - ref.loss) / ref.loss});
  }
}

/// Float against double at the paper's settings, for horizons of m/4 … m steps.
template <class SimD, class SimF, class ObjD, class ObjF>
void precision(const std::string& name, const SimD& sim_d, const SimF& sim_f, const ObjD& obj_d,
               const ObjF& obj_f, const Network<double>& net_d, const Matrix<double>& x0_d,
               Index m) {
  Network<float> net_f(net_d.layers());
  net_f.params() = net_d.params().cast<float>();
  const Matrix<float> x0_f = x0_d.cast<float>();
  for (const Index quarter : {1, 2, 3, 4}) {
    const Index h = m * quarter / 4;
    const Outcome d = run_engine(sim_d, net_d, obj_d, h, x0_d, false);
    const Outcome f = run_engine(sim_f, net_f, obj_f, h, x0_f, false);
    report({name, "precision", "float", h, 0, static_cast<double>(quarter) / 4, f.ms,
            relative(f.final_states, d.final_states), relative(f.gradient, d.gradient),
            std::abs(f.loss - d.loss) / std::abs(d.loss)});
  }
}

/// Writes the points so far; `announce` says so on stdout (once, at the end). Written after
/// each simulator's sweeps too, so that a signal in the half minute loses the simulator under
/// way, not those measured.
void write_csv(const std::string& path, bool announce = true) {
  std::string text = "sim,sweep,scalar,steps,nx,h,ms,state_error,grad_error,loss_error\n";
  char line[256];
  for (const auto& p : points) {
    std::snprintf(line, sizeof line, "%s,%s,%s,%lld,%lld,%.9g,%.6g,%.6e,%.6e,%.6e\n",
                  p.sim.c_str(), p.sweep.c_str(), p.scalar.c_str(),
                  static_cast<long long>(p.steps), static_cast<long long>(p.nx), p.h, p.ms,
                  p.state_error, p.grad_error, p.loss_error);
    text += line;
  }
  sbptt::write_file_atomically(path, text);
  if (announce) std::printf("\nwrote %s\n", path.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  std::string csv;
  bool integrators_only = false;
  try {
    sbptt::examples::CommandLine cli(
        "accuracy", "Discretisation and float error of each simulator and of its gradient g_R "
                    "(docs/benchmarks.md). Exit codes: 0 success, 1 error, 2 bad flag.");
    cli.path("--csv", csv, "also write every point as CSV here (plot: tools/plot_accuracy.py)");
    cli.flag("--integrators-only", "run only the cart pole's integrator axis",
             [&integrators_only] { integrators_only = true; });
    if (!cli.parse(argc, argv)) return sbptt::examples::with_streams_checked("accuracy", 0);
  } catch (const sbptt::InvalidArgument& e) {
    std::fprintf(stderr, "accuracy: %s\n", e.what());
    return 2;
  }
  try {
    if (!csv.empty()) sbptt::check_output_path(csv, "--csv");  // now, not after the sweeps
  } catch (const std::exception& e) {
    std::fprintf(stderr, "accuracy: %s\n", e.what());
    return 1;
  }
  try {
    std::printf("accuracy: %s code; ms of 1 thread\n", sbptt::instruction_set());
    std::printf("%-9s %-9s %-6s %6s %5s %10s %9s %11s %11s %11s\n", "sim", "sweep", "scalar",
                "steps", "Nx", "h", "ms", "state err", "g_R err", "loss err");
    sbptt::Rng rng(42);
    if (integrators_only) {
      sbptt::Rng same(42);  // the cart pole's data of the full run
      integrator_axis(mlp<double>(10, 1),
                      sbptt::cartpole_initial_states(cartpole_d(100), same, kBatch));
      if (!csv.empty()) write_csv(csv);
      return sbptt::examples::with_streams_checked("accuracy", 0);
    }
    {  // cart pole, 4 poles, T = 1 (paper: m = 100)
      const auto net = mlp<double>(10, 1);
      const Matrix<double> x0 = sbptt::cartpole_initial_states(cartpole_d(100), rng, kBatch);
      const auto make = [](auto s, Index m) {
        sbptt::CartPoleOptions o;
        o.steps = m;
        return sbptt::CartPole<decltype(s), 4>(o);
      };
      const auto objective = [](const auto& sim) {
        return sbptt::cartpole_objective<typename std::decay_t<decltype(sim)>::Scalar, 4>();
      };
      const std::vector<Index> steps = {25, 50, 100, 200, 400, 800};
      sweep_steps<double>("cartpole", steps, make, objective, net, x0, 1.0);
      sweep_steps<float>("cartpole", steps, make, objective, net, x0, 1.0);
      precision("cartpole", make(double{}, 100), make(float{}, 100), objective(make(0.0, 100)),
                objective(make(0.0f, 100)), net, x0, 100);
      integrator_axis(net, x0);
    }
    if (!csv.empty()) write_csv(csv, false);
    {  // guidance 2-4, T = 4 (paper: m = 60)
      const auto make = [](auto s, Index m) {
        sbptt::GuidanceOptions o;
        o.steps = m;
        return sbptt::GuidanceByRepulsion<decltype(s), 2, 4>(o);
      };
      const auto objective = [](const auto& sim) { return sbptt::guidance_objective(sim, 0.1); };
      const auto net = mlp<double>(24, 4);
      const Matrix<double> x0 = sbptt::guidance_initial_states(make(0.0, 60), rng, kBatch);
      const std::vector<Index> steps = {15, 30, 60, 120, 240, 480, 960, 1920};
      sweep_steps<double>("guidance", steps, make, objective, net, x0, 4.0);
      sweep_steps<float>("guidance", steps, make, objective, net, x0, 4.0);
      precision("guidance", make(0.0, 60), make(0.0f, 60), objective(make(0.0, 60)),
                objective(make(0.0f, 60)), net, x0, 60);
    }
    if (!csv.empty()) write_csv(csv, false);
    {  // quantum, Nx = 32, T = 8 (paper: m = 128), target n = 4
      const auto net = cnn();
      const auto make = [](auto s, Index m) { return quantum<decltype(s)>(32, m); };
      const auto objective = [](const auto& sim) { return sbptt::quantum_objective(sim, 4); };
      const Matrix<double> x0 = make(0.0, 128).initial_states(rng, kBatch);
      const std::vector<Index> steps = {32, 64, 128, 256, 512, 1024, 2048, 4096};
      sweep_steps<double>("quantum", steps, make, objective, net, x0, 8.0);
      sweep_steps<float>("quantum", steps, make, objective, net, x0, 8.0);
      sweep_grid<double>(net);
      sweep_grid<float>(net);
      precision("quantum", make(0.0, 128), make(0.0f, 128), objective(make(0.0, 128)),
                objective(make(0.0f, 128)), net, x0, 128);
    }
    std::printf("\nobserved orders in double (slope of log error against log h; over the 4 "
                "finest points, and over the finest pair):\n");
    for (const auto& [sim, sweep] : std::vector<std::pair<std::string, std::string>>{
             {"cartpole", "dt"}, {"cartpole", "sie"}, {"cartpole", "rk2"}, {"cartpole", "rk4"},
             {"guidance", "dt"}, {"quantum", "dt"}, {"quantum", "nx"}}) {
      std::printf("  %-8s in %-3s: final state %.2f (%.2f), g_R %.2f (%.2f)\n", sim.c_str(),
                  sweep.c_str(), order(sim, sweep, "double", false, 4),
                  order(sim, sweep, "double", false, 2), order(sim, sweep, "double", true, 4),
                  order(sim, sweep, "double", true, 2));
    }
    if (!csv.empty()) write_csv(csv);
    return sbptt::examples::with_streams_checked("accuracy", 0);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "accuracy: %s\n", e.what());
    return 1;
  }
}
