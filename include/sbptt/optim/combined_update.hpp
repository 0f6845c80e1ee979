#pragma once
/// \file The paper's combined update (C) and the one path every update takes to the optimizer.
///
/// Per component, from the modified vector g_M and the true gradient g_R (both size n):
///
///     g_C[i] = g_M[i]   if sign(g_M[i]) == sign(g_R[i])
///              0        otherwise
///
/// with TF's sign: sign(0) = 0, so one zero and one non-zero give 0, and two zeros give
/// g_M[i] = 0. The modified vector's *value* is kept, never the gradient's, so the balanced
/// magnitudes of g_M survive; the mask only removes the components that would push against
/// the true gradient. Hence g_C · g_R ≥ 0 (never an ascent direction of L) and
/// |g_C[i]| ≤ |g_M[i]|, which is what stops the curl of g_M from making Adam orbit a minimum.
///
/// A NaN in either vector never counts as agreeing, so that component becomes 0. For g_R this
/// is what TF does (an overflowing regular gradient is masked out and training continues). For
/// g_M it is our choice: with a sign that maps NaN to 0, as Eigen's older sign functor under
/// tf.sign does, a NaN in g_M would pass wherever g_R is 0, and poison the optimizer state.
/// The sign and the agreement rule are core/sign.hpp's, shared with the diagnostics.
///
/// Order, as in the reference: combine → clip → optimizer step. `ClippedUpdate` is the clip →
/// step half and serves the non-combined modes; `CombinedUpdate` adds the combination in front
/// of the same object, so both paths clip and step identically.
#include <cmath>
#include <concepts>
#include <utility>

#include "sbptt/core/error.hpp"
#include "sbptt/core/sign.hpp"  // signs_agree, agreement_pass, sign_agreement
#include "sbptt/core/types.hpp"
#include "sbptt/optim/clip.hpp"
#include "sbptt/optim/step_checks.hpp"

namespace sbptt {

/// An optimizer on flat vectors: a member type `Scalar` and `step(params, grad)` updating
/// `params` (size n) in place from `grad` (size n). `Adam` and `Sgd` model it.
template <class O>
concept FlatOptimizer = std::floating_point<typename O::Scalar> &&
    requires(O& optimizer, Vector<typename O::Scalar>& params,
             const Vector<typename O::Scalar>& grad) {
      optimizer.step(params, grad);
    };

namespace detail {

/// `combine`, returning how many components kept g_M; a size mismatch is refused in `caller`'s
/// name.
template <std::floating_point Scalar>
Index combine_counting(const Vector<Scalar>& g_modified, const Vector<Scalar>& g_regular,
                       Vector<Scalar>& out, const char* caller = "combine") {
  require_same_size(g_modified, g_regular, caller);
  // Sizes are equal here, so the resize is a no-op when `out` aliases an input, and each
  // component is read before it is written: aliasing either input is safe.
  out.resize(g_modified.size());
  return agreement_pass<Scalar>(g_modified.data(), g_regular.data(), g_modified.size(),
                                out.data(), nullptr);
}

}  // namespace detail

/// The combined vector g_C (size n) from g_M and g_R (size n each); throws `InvalidArgument`
/// on a size mismatch. `out` is resized and may be the same object as either input.
template <std::floating_point Scalar>
void combine(const Vector<Scalar>& g_modified, const Vector<Scalar>& g_regular,
             Vector<Scalar>& out) {
  (void)detail::combine_counting(g_modified, g_regular, out);
}

/// clip → `Inner::step`: the update path of the non-combined modes (R, M, S, N). Keeps a
/// scratch copy of the vector so that the caller's gradient stays untouched.
template <FlatOptimizer Inner>
class ClippedUpdate {
public:
  using Scalar = typename Inner::Scalar;

  /// Throws `InvalidArgument` if `threshold` is not finite and > 0 for a clipping mode.
  explicit ClippedUpdate(Inner inner = Inner{}, ClipMode mode = ClipMode::None,
                         Scalar threshold = Scalar(1))
      : inner_(std::move(inner)), mode_(mode), threshold_(threshold) {
    detail::require_clip_threshold(mode_, threshold_);
  }

  /// Clips a copy of `grad` (size n) and steps `params` (size n) with it. A step refused
  /// (sizes that differ, or the inner optimizer's own checks) changes nothing.
  void step(Vector<Scalar>& params, const Vector<Scalar>& grad) {
    detail::require_step_sizes(params, grad, 0, false, "ClippedUpdate::step");
    scratch_ = grad;
    clip_and_step(params, scratch_);
  }

  /// As `step`, but clips `update` (size n) itself: for callers that own a scratch vector
  /// and do not need it afterwards (saves a copy of n). Refused for its sizes, it leaves
  /// `update` as it was; refused by the inner optimizer, `update` is clipped, nothing else.
  void step_in_place(Vector<Scalar>& params, Vector<Scalar>& update) {
    detail::require_step_sizes(params, update, 0, false, "ClippedUpdate::step_in_place");
    clip_and_step(params, update);
  }

  /// ‖vector‖² before clipping, of the last step (the reference's logged "update size").
  [[nodiscard]] double last_norm2() const { return last_norm2_; }

  [[nodiscard]] ClipMode clip_mode() const { return mode_; }
  [[nodiscard]] Scalar clip_threshold() const { return threshold_; }
  [[nodiscard]] Inner& inner() { return inner_; }
  [[nodiscard]] const Inner& inner() const { return inner_; }

private:
  template <FlatOptimizer>
  friend class CombinedUpdate;  // checks the sizes in its own name, then clips and steps

  /// The figure it logs is set only once the inner optimizer has taken the step.
  void clip_and_step(Vector<Scalar>& params, Vector<Scalar>& update) {
    const Scalar norm = clip(update, mode_, threshold_);
    inner_.step(params, update);
    // Squared in double: a finite float norm beyond 1.8e19 would overflow to inf.
    last_norm2_ = static_cast<double>(norm) * static_cast<double>(norm);
  }

  Inner inner_;
  ClipMode mode_;
  Scalar threshold_;
  Vector<Scalar> scratch_;
  double last_norm2_ = 0;
};

/// combine → clip → `Inner::step`: the paper's C mode, as the reference orders it.
template <FlatOptimizer Inner>
class CombinedUpdate {
public:
  using Scalar = typename Inner::Scalar;

  /// Throws `InvalidArgument` if `threshold` is not finite and > 0 for a clipping mode.
  explicit CombinedUpdate(Inner inner = Inner{}, ClipMode mode = ClipMode::None,
                          Scalar threshold = Scalar(1))
      : clipped_(std::move(inner), mode, threshold) {}

  /// Steps `params` (size n) with combine(g_M, g_R), clipped; g_M and g_R have size n.
  void step(Vector<Scalar>& params, const Vector<Scalar>& g_modified,
            const Vector<Scalar>& g_regular) {
    detail::require_step_sizes(params, g_modified, 0, false, "CombinedUpdate::step");
    const Index agreeing =
        detail::combine_counting(g_modified, g_regular, combined_, "CombinedUpdate::step");
    clipped_.clip_and_step(params, combined_);
    last_agreement_ = detail::agreement_fraction<Scalar>(agreeing, g_modified.size());
  }

  /// As `step`, with g_C already formed (size n, e.g. `GradientPair::combined`, which the
  /// engine forms in the pass that compares g_M with g_R): clips `combined` in place and steps
  /// `params` (size n) with it. `agreement` in [0, 1] is the fraction of g_M that it kept,
  /// reported by `last_agreement`. A step refused changes nothing (see `ClippedUpdate`).
  void step_combined(Vector<Scalar>& params, Vector<Scalar>& combined, Scalar agreement) {
    detail::require(agreement >= Scalar(0) && agreement <= Scalar(1),
                    "CombinedUpdate::step_combined: agreement = ", agreement,
                    "; expected a fraction in [0, 1]");
    detail::require_step_sizes(params, combined, 0, false, "CombinedUpdate::step_combined");
    clipped_.clip_and_step(params, combined);
    last_agreement_ = agreement;
  }

  /// ‖g_C‖² before clipping, of the last step.
  [[nodiscard]] double last_norm2() const { return clipped_.last_norm2(); }
  /// Fraction of components whose signs agreed in the last step (see `sign_agreement`).
  [[nodiscard]] Scalar last_agreement() const { return last_agreement_; }

  [[nodiscard]] ClipMode clip_mode() const { return clipped_.clip_mode(); }
  [[nodiscard]] Scalar clip_threshold() const { return clipped_.clip_threshold(); }
  [[nodiscard]] Inner& inner() { return clipped_.inner(); }
  [[nodiscard]] const Inner& inner() const { return clipped_.inner(); }

private:
  ClippedUpdate<Inner> clipped_;
  Vector<Scalar> combined_;
  Scalar last_agreement_ = 1;
};

}  // namespace sbptt
