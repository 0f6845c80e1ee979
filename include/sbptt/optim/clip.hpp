#pragma once
/// \file Gradient clipping as the reference ran it: Keras `clipvalue` and `global_clipnorm`.
///
/// The paper treats clipping as a variant of every method (none, value 1.0, global norm 1.0),
/// applied to whatever vector reaches the optimizer, i.e. to g_C after the sign combination.
/// Norm clipping of the one flat parameter vector is Keras's *global* norm (all variables
/// measured jointly), not its per-variable `clipnorm`, which the reference never used.
#include <algorithm>
#include <cmath>
#include <concepts>
#include <limits>
#include <string>
#include <string_view>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// How `clip` limits an update vector.
enum class ClipMode {
  None,   ///< leave the vector as it is
  Value,  ///< clamp every component to [−t, t] (Keras `clipvalue=t`)
  Norm,   ///< rescale so that ‖g‖₂ ≤ t (Keras `global_clipnorm=t`, `tf.clip_by_global_norm`)
};

/// "none", "value" or "norm".
[[nodiscard]] inline std::string to_string(ClipMode mode) {
  switch (mode) {
    case ClipMode::None: return "none";
    case ClipMode::Value: return "value";
    case ClipMode::Norm: return "norm";
  }
  throw InvalidArgument(detail::concat("ClipMode with value ", static_cast<int>(mode),
                                       " is not one of none, value, norm"));
}

/// Inverse of `to_string`: accepts exactly "none", "value", "norm" (lower case, the spelling
/// used on command lines and in logs); anything else throws `InvalidArgument` naming it.
[[nodiscard]] inline ClipMode parse_clip_mode(std::string_view text) {
  if (text == "none") return ClipMode::None;
  if (text == "value") return ClipMode::Value;
  if (text == "norm") return ClipMode::Norm;
  throw InvalidArgument(detail::concat("clip mode \"", text,
                                       "\" is not recognised; expected one of none, value, norm"));
}

namespace detail {

/// Throws unless `threshold` can serve `mode` (any value is accepted for None, which never
/// reads it, so callers can pass a configured threshold unconditionally).
template <std::floating_point Scalar>
void require_clip_threshold(ClipMode mode, Scalar threshold) {
  if (mode == ClipMode::None) return;
  require(std::isfinite(threshold) && threshold > Scalar(0), "clip threshold = ", threshold,
          " for clip mode ", to_string(mode), "; expected a finite number > 0");
}

}  // namespace detail

/// Clips `g` (size n, modified in place) and returns its global L2 norm *before* clipping,
/// for every mode (the reference logs the pre-clip size of the applied vector).
///
/// - `Value`: g_i ← min(max(g_i, −t), t). NaN components stay NaN.
/// - `Norm`:  g ← g · t / max(‖g‖, t), so a vector already inside the ball is untouched
///   bit for bit. A non-finite norm turns every component into NaN, as
///   `tf.clip_by_global_norm` documents; the returned norm tells the caller why.
///
/// The norm is Eigen's `stableNorm`, so a finite float vector whose squares overflow still
/// gets a finite norm and a finite clipped result (TF would return NaN there).
template <std::floating_point Scalar>
Scalar clip(Vector<Scalar>& g, ClipMode mode, Scalar threshold) {
  detail::require_clip_threshold(mode, threshold);
  const Scalar norm = g.size() == 0 ? Scalar(0) : g.stableNorm();
  switch (mode) {
    case ClipMode::None: break;
    case ClipMode::Value:
      for (Index i = 0; i < g.size(); ++i) {
        // std::clamp would return NaN too, but spelling the comparisons out keeps that explicit.
        if (g(i) > threshold) g(i) = threshold;
        else if (g(i) < -threshold) g(i) = -threshold;
      }
      break;
    case ClipMode::Norm:
      if (!std::isfinite(norm)) {
        g.setConstant(std::numeric_limits<Scalar>::quiet_NaN());
      } else if (norm > threshold) {
        g *= threshold / norm;
      }
      break;
  }
  return norm;
}

}  // namespace sbptt
