#pragma once
/// \file The whole-gradient checker: the engine's gradient of the rollout loss against central
/// differences of that loss, for any simulator, controller and objective.
///
/// Two checks, the two gradients that have a finite-difference meaning:
/// - R: the Full sweep's g = ∂L/∂θ of the batch loss L(θ) (objective.hpp) against
///   (L(θ + h eᵢ) − L(θ − h eᵢ)) / 2h, h = step · max(1, |θᵢ|), for every parameter or a seeded
///   sample of `max_parameters` of them. This covers the simulator's VJP, the controller's two
///   products, the loss seeds and the control regulariser together;
/// - the objective's own ∂ℓ/∂x against central differences of ℓ at states the rollout visits
///   (up to `max_states` scored states of up to `max_samples` samples).
/// The modified and stopped modes are not gradients of any loss, so they have no
/// finite-difference twin; they share every product with R.
///
/// Tolerances that hold for a correct, smooth scene (the library's tests): `worst() < 1e-5` in
/// double and `< 5e-2` in float at the default step. Chaotic or long rollouts amplify the
/// finite-difference error like any perturbation; shorten the horizon to check them.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/objective.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"

namespace sbptt {

/// What `check_gradient` compares (see the file comment).
struct GradientCheckOptions {
  Index max_parameters = 64;  ///< parameters compared (all if the network has fewer)
  Index max_states = 5;       ///< scored states per sample at which ∂ℓ/∂x is compared
  Index max_samples = 4;      ///< samples at whose states ∂ℓ/∂x is compared
  std::uint64_t seed = 1;     ///< picks the parameters when there are more than max_parameters
  double step = 0;            ///< central-difference scale; 0 = ∛ε of the Scalar
};

/// Result of `check_gradient`: relative errors as in `relative_error` (max |Δ| / max |fd|).
template <class Scalar>
struct GradientCheck {
  Scalar loss = 0;               ///< the batch loss L(θ) at the checked parameters
  Scalar regular_error = 0;      ///< engine's R gradient against differences of L
  Scalar state_loss_error = 0;   ///< objective's ∂ℓ/∂x against differences of ℓ
  Index parameters_checked = 0;  ///< number of parameters compared
  /// The larger error, or NaN if either is NaN.
  [[nodiscard]] Scalar worst() const {
    return worst_error({regular_error, state_loss_error});
  }
};

/// Checks the engine's R gradient and the objective's state gradient at the current parameters
/// of `controller` for the batch `initial_states` (state_dim × B) rolled out `steps` steps.
/// The parameters are perturbed in place and restored exactly.
template <class Sim, class Ctrl, class Loss>
[[nodiscard]] GradientCheck<typename Sim::Scalar> check_gradient(
    const Sim& sim, Ctrl& controller, const Objective<Loss>& objective, Index steps,
    const Matrix<typename Sim::Scalar>& initial_states, const GradientCheckOptions& options = {}) {
  using Scalar = typename Sim::Scalar;
  using State = typename Sim::State;
  detail::require(options.max_parameters > 0 && options.max_states > 0 &&
                      options.max_samples > 0 && options.step >= 0,
                  "check_gradient: max_parameters = ", options.max_parameters,
                  ", max_states = ", options.max_states, ", max_samples = ", options.max_samples,
                  ", step = ", options.step, "; expected counts >= 1 and a step >= 0");
  const Scalar step = options.step > 0 ? static_cast<Scalar>(options.step)
                                       : default_fd_step<Scalar>();
  Engine<Sim, Ctrl, Loss> engine(sim, controller, objective, steps);
  GradientCheck<Scalar> result;
  result.loss = engine.forward(initial_states);
  Vector<Scalar> gradient;
  engine.reverse(FlowMode::Full, gradient);

  // The parameters compared: all, or a seeded sample (partial Fisher–Yates).
  std::vector<Index> chosen(static_cast<std::size_t>(controller.num_params()));
  std::iota(chosen.begin(), chosen.end(), Index(0));
  const auto count = std::min<std::size_t>(chosen.size(),
                                           static_cast<std::size_t>(options.max_parameters));
  Rng rng(options.seed);
  for (std::size_t i = 0; i < count; ++i) {
    const auto remaining = static_cast<double>(chosen.size() - i);
    const auto j = i + std::min(static_cast<std::size_t>(rng.uniform() * remaining),
                                chosen.size() - i - 1);
    std::swap(chosen[i], chosen[j]);
  }
  chosen.resize(count);
  Vector<Scalar> analytic(static_cast<Index>(count)), differences(static_cast<Index>(count));
  for (std::size_t c = 0; c < count; ++c) {
    const Index i = chosen[c];
    const Scalar original = controller.params()(i);
    const Scalar h = step * std::max(Scalar(1), std::abs(original));
    controller.params()(i) = original + h;
    const Scalar plus = engine.evaluate(initial_states);
    controller.params()(i) = original - h;
    const Scalar minus = engine.evaluate(initial_states);
    controller.params()(i) = original;
    analytic(static_cast<Index>(c)) = gradient(i);
    differences(static_cast<Index>(c)) = (plus - minus) / (Scalar(2) * h);
  }
  result.parameters_checked = static_cast<Index>(count);
  result.regular_error = relative_error<Scalar>(analytic, differences);

  // ∂ℓ/∂x at scored states of the stored rollout, evenly spread over the scored steps.
  const Index first = objective.timing == LossTiming::Final ? steps : 1;
  const Index scored = steps - first + 1;
  const Index states = std::min(options.max_states, scored);
  const Index samples = std::min(options.max_samples, initial_states.cols());
  State x(sim.state_dim()), grad(sim.state_dim());
  auto loss_at = [&](const Vector<Scalar>& point, Vector<Scalar>& out) {
    x = point;
    out.resize(1);
    out(0) = objective.state_loss(x, static_cast<State*>(nullptr));
  };
  for (Index s = 0; s < states; ++s) {
    const Index n = first + (states == 1 ? 0 : s * (scored - 1) / (states - 1));
    for (Index b = 0; b < samples; ++b) {
      const Vector<Scalar> point = engine.trajectory().states[static_cast<std::size_t>(n)].col(b);
      x = point;
      objective.state_loss(x, &grad);
      const Matrix<Scalar> fd = finite_difference_jacobian<Scalar>(loss_at, point, 1, step);
      const Matrix<Scalar> own = Vector<Scalar>(grad).transpose();
      result.state_loss_error =
          worst_error({result.state_loss_error, relative_error<Scalar>(own, fd)});
    }
  }
  return result;
}

}  // namespace sbptt
