#pragma once
/// \file The two contracts everything else is built on: `Simulator` and `Controller`.
///
/// A concept failure inside a template is hard to read, so each requirement is also a concept
/// of its own, and `static_assert_simulator<T>()` / `static_assert_controller<T>()` report the
/// first missing member in plain words. The engine calls them on its template arguments.
#include <concepts>
#include <string>

#include "sbptt/core/types.hpp"

namespace sbptt {
namespace detail {

template <class S>
concept HasSimulatorTypes = requires {
  typename S::Scalar;
  typename S::State;
  typename S::Control;
};

template <class S>
concept HasSimulatorSizes = HasSimulatorTypes<S> && requires(const S& sim) {
  { sim.state_dim() } -> std::convertible_to<Index>;
  { sim.control_dim() } -> std::convertible_to<Index>;
};

template <class S>
concept HasSimulatorStep = HasSimulatorTypes<S> &&
    requires(const S& sim, const typename S::State& x, const typename S::Control& u,
             typename S::State& x_next) {
      sim.step(x, u, x_next);
    };

template <class S>
concept HasSimulatorJacobians = HasSimulatorTypes<S> &&
    requires {
      typename S::StateJacobian;
      typename S::ControlJacobian;
    } &&
    requires(const S& sim, const typename S::State& x, const typename S::Control& u,
             typename S::StateJacobian& a, typename S::ControlJacobian& b) {
      sim.jacobians(x, u, a, b);
    };

template <class S>
concept HasSimulatorVjp = HasSimulatorTypes<S> &&
    requires(const S& sim, const typename S::State& x, const typename S::Control& u,
             const typename S::State& lambda, typename S::State* lambda_x,
             typename S::Control* lambda_u) {
      sim.vjp(x, u, lambda, lambda_x, lambda_u);
    };

template <class C>
concept HasControllerTypes = requires {
  typename C::Scalar;
  typename C::Workspace;
  requires std::default_initializable<typename C::Workspace>;
};

template <class C>
concept HasControllerSizes = HasControllerTypes<C> && requires(const C& c) {
  { c.input_dim() } -> std::convertible_to<Index>;
  { c.output_dim() } -> std::convertible_to<Index>;
  { c.num_params() } -> std::convertible_to<Index>;
};

template <class C>
concept HasControllerParams = HasControllerTypes<C> && requires(C& c, const C& cc) {
  { cc.params() } -> std::convertible_to<const Vector<typename C::Scalar>&>;
  { c.params() } -> std::same_as<Vector<typename C::Scalar>&>;
};

template <class C>
concept HasControllerForward = HasControllerTypes<C> &&
    requires(const C& c, const Matrix<typename C::Scalar>& inputs,
             Matrix<typename C::Scalar>& outputs, typename C::Workspace& workspace) {
      c.forward(inputs, outputs, workspace);
    };

template <class C>
concept HasControllerBackward = HasControllerTypes<C> &&
    requires(const C& c, const typename C::Workspace& workspace,
             const Matrix<typename C::Scalar>& output_adjoint, Vector<typename C::Scalar>& grad,
             Matrix<typename C::Scalar>* input_adjoint) {
      c.backward(workspace, output_adjoint, grad, input_adjoint);
    };

}  // namespace detail

/// A differentiable, immutable, thread-safe time stepper `x_next = P(x, u)`: what the engine
/// calls, and nothing more.
///
/// Members (all `const`):
/// - `using Scalar, State, Control` (Eigen column vectors of sizes `state_dim()` and
///   `control_dim()`);
/// - `Index state_dim()`, `Index control_dim()`;
/// - `void step(const State& x, const Control& u, State& x_next)`;
/// - `void vjp(const State& x, const Control& u, const State& lambda, State* lambda_x,
///   Control* lambda_u)` setting `*lambda_x = Aᵀ lambda`, `*lambda_u = Bᵀ lambda` with
///   A = ∂x_next/∂x, B = ∂x_next/∂u; a null pointer skips that product. `lambda_x` never
///   aliases `lambda`.
///
/// A time step `dt()` and the dense Jacobians are not required: the engine uses neither.
/// `SimulatorWithJacobians` adds the Jacobians, which `check_jacobians` then checks too.
template <class S>
concept Simulator = detail::HasSimulatorSizes<S> && detail::HasSimulatorStep<S> &&
                    detail::HasSimulatorVjp<S>;

/// A `Simulator` that says why it answered calls with NaN: `take_refusals()` returns its
/// record of the calls it refused since the last such call (and forgets them), and
/// `describe(record)`, found by argument-dependent lookup, puts the record in words ("" when
/// it holds none). The trainer adds those words to its non-finite events. `MujocoSimulator`
/// is one ("MuJoCo refused a call (a step or its derivatives): its contact buffer is full
/// (increase nconmax above 100)").
template <class S>
concept ExplainsRefusals = Simulator<S> && requires(const S& sim) {
  { describe(sim.take_refusals()) } -> std::convertible_to<std::string>;
};

namespace detail {

/// The words of `sim`'s refusals since the last call, or "" from a simulator that gives none.
template <class S>
[[nodiscard]] std::string take_refusal_note(const S& sim) {
  if constexpr (ExplainsRefusals<S>) {
    return describe(sim.take_refusals());
  } else {
    return {};
  }
}

/// `note` after `separator` (`"; "` + "MuJoCo refused …"), or "" when there is no note.
[[nodiscard]] inline std::string note_after(const char* separator, const std::string& note) {
  return note.empty() ? std::string() : separator + note;
}

}  // namespace detail

/// A `Simulator` that also forms its dense Jacobians:
/// - `using StateJacobian, ControlJacobian` (Eigen matrices);
/// - `void jacobians(const State& x, const Control& u, StateJacobian& A, ControlJacobian& B)`
///   with `A = ∂x_next/∂x` (state_dim × state_dim), `B = ∂x_next/∂u` (state_dim × control_dim).
template <class S>
concept SimulatorWithJacobians = Simulator<S> && detail::HasSimulatorJacobians<S>;

/// A `Simulator` that also steps and differentiates a whole batch in one call, columns being
/// samples (`Schrodinger1D` runs its samples side by side in SIMD lanes):
/// - `void step_batch(const Matrix<Scalar>& X, const Matrix<Scalar>& U, Matrix<Scalar>& X_next)`
///   with X state_dim × B, U control_dim × B, X_next resized to state_dim × B;
/// - `void vjp_batch(const Matrix<Scalar>& X, const Matrix<Scalar>& U, const Matrix<Scalar>&
///   Lambda, Matrix<Scalar>* Lambda_x, Matrix<Scalar>* Lambda_u)`, `vjp` per column, a null
///   pointer skipping that product.
/// Column b of a result may differ from `step` / `vjp` of column b by rounding but must depend
/// neither on the other columns nor on b. The engine then uses these for every rollout and
/// sweep, and for both sweeps of the combined update in one call of 2B columns (by
/// `vjp_batch_pair` when the simulator has it, `PairedBatchSimulator` below).
template <class S>
concept BatchSimulator =
    Simulator<S> && requires(const S& sim, const Matrix<typename S::Scalar>& x,
                             const Matrix<typename S::Scalar>& u, Matrix<typename S::Scalar>& out,
                             Matrix<typename S::Scalar>* out_x, Matrix<typename S::Scalar>* out_u) {
      sim.step_batch(x, u, out);
      sim.vjp_batch(x, u, x, out_x, out_u);
    };

/// A `BatchSimulator` that also differentiates two adjoints per sample in one call:
/// `void vjp_batch_pair(X, U, Lambda_1, Lambda_2, Lambda_x_1, Lambda_x_2, Lambda_u_1,
/// Lambda_u_2)`, the two halves of `vjp_batch([X X], [U U], [Lambda_1 Lambda_2], …)` without
/// forming those matrices. The combined update's two sweeps then need no copies in and out of
/// a 2B-column call (guidance's C/R epoch ratio 0.002–0.008 lower on average in three sets of
/// rounds, docs/benchmark-runs-zen4.md, thirty-eighth run).
template <class S>
concept PairedBatchSimulator =
    BatchSimulator<S> && requires(const S& sim, const Matrix<typename S::Scalar>& x,
                                  Matrix<typename S::Scalar>* out) {
      sim.vjp_batch_pair(x, x, x, x, out, out, out, out);
    };

/// A parametric batch map `Y = N(X; θ)` with one flat parameter vector θ.
///
/// Members:
/// - `using Scalar`, `using Workspace` (default-constructible; what backward needs);
/// - `Index input_dim()`, `output_dim()`, `num_params()`;
/// - `const Vector<Scalar>& params() const`, `Vector<Scalar>& params()` (size num_params());
/// - `void forward(const Matrix<Scalar>& X, Matrix<Scalar>& Y, Workspace& ws) const` with X
///   input_dim × B and Y resized to output_dim × B; `ws` records what backward needs;
/// - `void backward(const Workspace& ws, const Matrix<Scalar>& dY, Vector<Scalar>& grad,
///   Matrix<Scalar>* dX) const`: **adds** (∂N/∂θ)ᵀ dY, summed over the batch, to `grad`; if
///   `dX` is not null, sets `*dX = (∂N/∂x)ᵀ dY` (input_dim × B). Passing null is how the
///   gradient is stopped at the network input, and it skips that work; what is added to
///   `grad` must be the same numbers either way (the combined update's pair on one thread
///   takes g_M's first terms from g_R's, bptt/reverse_sweeps.hpp).
template <class C>
concept Controller = detail::HasControllerSizes<C> && detail::HasControllerParams<C> &&
                     detail::HasControllerForward<C> && detail::HasControllerBackward<C>;

/// A `Controller` that can prepare its parameters once for many calls (`Network` packs its
/// weights): `using PackedWeights` (default-constructible), `void pack(PackedWeights&) const`
/// from the current θ, and `forward` / `backward` overloads that take `const PackedWeights&`
/// as their last argument and give the same results as the plain ones. The engine packs once
/// per rollout and uses the packed overloads for every step of it.
template <class C>
concept PackingController =
    Controller<C> && std::default_initializable<typename C::PackedWeights> &&
    requires(const C& c, typename C::PackedWeights& packed, const typename C::PackedWeights& cp,
             const Matrix<typename C::Scalar>& x, Matrix<typename C::Scalar>& y,
             typename C::Workspace& ws, const typename C::Workspace& cws,
             Vector<typename C::Scalar>& grad, Matrix<typename C::Scalar>* dx) {
      c.pack(packed);
      c.forward(x, y, ws, cp);
      c.backward(cws, x, grad, dx, cp);
    };

/// A `PackingController` whose packed forward pass can be done in parts, as `Network`'s can:
/// `void size_forward(Index B, Workspace& ws) const` sizes `ws` for B samples, then
/// `void forward_columns(X, first, Y, ws, packed) const` does for the samples first … first +
/// X.cols() − 1 what the packed `forward` of the whole batch does (Y: their outputs), bit for
/// bit, and may run at once with calls on other samples. The engine then rolls out a batch's
/// columns on several threads.
template <class C>
concept ColumnSplitController =
    PackingController<C> &&
    requires(const C& c, const typename C::PackedWeights& packed,
             const Matrix<typename C::Scalar>& x, Matrix<typename C::Scalar>& y,
             typename C::Workspace& ws, Index index) {
      c.size_forward(index, ws);
      c.forward_columns(x, index, y, ws, packed);
    };

/// A `PackingController` whose backward splits into two halves, as `Network`'s does:
/// `using LayerAdjoints` (default-constructible), `void backward_inputs(ws, dY, dX, packed,
/// adjoints) const`, which does what the packed `backward` does to `dX` and records what the
/// parameter products need in `adjoints`, and `void add_param_gradient(ws, adjoints, grad)
/// const`, which adds what the packed `backward` adds to `grad`. The engine then runs the
/// parameter half of one step on a second thread while the next step's input half proceeds.
template <class C>
concept SplitBackwardController =
    PackingController<C> && std::default_initializable<typename C::LayerAdjoints> &&
    requires(const C& c, const typename C::Workspace& ws, const Matrix<typename C::Scalar>& dy,
             Matrix<typename C::Scalar>* dx, const typename C::PackedWeights& packed,
             typename C::LayerAdjoints& adjoints, const typename C::LayerAdjoints& recorded,
             Vector<typename C::Scalar>& grad) {
      c.backward_inputs(ws, dy, dx, packed, adjoints);
      c.add_param_gradient(ws, recorded, grad);
    };

/// A `SplitBackwardController` that also adds the parameter products of a column-scaled seed:
/// `void add_param_gradient(ws, adjoints, scales, scaled, grad) const` adds what the packed
/// `backward` adds for dY·diag(scales) (`scales` 1 × B) from adjoints recorded with dY, using
/// the `LayerAdjoints` `scaled` as its workspace. The backward pass is linear in each column
/// of dY, so for a one-output controller one pass with dY = 1 serves every seed: the engine's
/// combined update then runs one backward pass for both sweeps.
template <class C>
concept SeedScalingController =
    SplitBackwardController<C> &&
    requires(const C& c, const typename C::Workspace& ws,
             const typename C::LayerAdjoints& recorded, const Matrix<typename C::Scalar>& scales,
             typename C::LayerAdjoints& scaled, Vector<typename C::Scalar>& grad) {
      c.add_param_gradient(ws, recorded, scales, scaled, grad);
    };

/// Compile-time check with a readable message per missing member; returns true.
template <class S>
consteval bool static_assert_simulator() {
  static_assert(detail::HasSimulatorTypes<S>,
                "sbptt::Simulator: the type needs member types Scalar, State and Control");
  static_assert(detail::HasSimulatorSizes<S>,
                "sbptt::Simulator: the type needs const members state_dim() and control_dim() "
                "(convertible to Index)");
  static_assert(detail::HasSimulatorStep<S>,
                "sbptt::Simulator: the type needs `void step(const State& x, const Control& u, "
                "State& x_next) const`");
  static_assert(detail::HasSimulatorVjp<S>,
                "sbptt::Simulator: the type needs `void vjp(const State& x, const Control& u, "
                "const State& lambda, State* lambda_x, Control* lambda_u) const`");
  return true;
}

/// Compile-time check with a readable message per missing member; returns true.
template <class C>
consteval bool static_assert_controller() {
  static_assert(detail::HasControllerTypes<C>,
                "sbptt::Controller: the type needs member types Scalar and a "
                "default-constructible Workspace");
  static_assert(detail::HasControllerSizes<C>,
                "sbptt::Controller: the type needs const members input_dim(), output_dim() and "
                "num_params() convertible to Index");
  static_assert(detail::HasControllerParams<C>,
                "sbptt::Controller: the type needs `const Vector<Scalar>& params() const` and "
                "`Vector<Scalar>& params()`");
  static_assert(detail::HasControllerForward<C>,
                "sbptt::Controller: the type needs `void forward(const Matrix<Scalar>& X, "
                "Matrix<Scalar>& Y, Workspace& ws) const`");
  static_assert(detail::HasControllerBackward<C>,
                "sbptt::Controller: the type needs `void backward(const Workspace& ws, const "
                "Matrix<Scalar>& dY, Vector<Scalar>& grad, Matrix<Scalar>* dX) const`");
  return true;
}

/// A per-sample state loss: `Scalar operator()(const State& x, State* grad) const` returns
/// ℓ(x) and, when `grad` is not null, sets `*grad = ∂ℓ/∂x` (state_dim).
template <class Loss, class State>
concept StateLoss = requires(const Loss& loss, const State& x, State* grad) {
  { loss(x, grad) } -> std::convertible_to<typename State::Scalar>;
};

}  // namespace sbptt
