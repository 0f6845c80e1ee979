#pragma once
/// \file What a forward pass and a reverse sweep report besides the loss and the gradient, and
/// the pair of sweeps that the combined update needs (`GradientPair`).
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string_view>
#include <vector>

#include "sbptt/core/error.hpp"
#include "sbptt/core/sign.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt {

/// The kind of value that first turned NaN or Inf. `Parameter`: a parameter that the
/// optimizer's step made NaN or Inf from a finite gradient (a learning rate too large, say).
enum class Quantity { Loss, State, Control, Adjoint, Gradient, Parameter };

[[nodiscard]] constexpr std::string_view to_string(Quantity quantity) {
  switch (quantity) {
    case Quantity::Loss: return "loss";
    case Quantity::State: return "state";
    case Quantity::Control: return "control";
    case Quantity::Adjoint: return "adjoint";
    case Quantity::Gradient: return "gradient";
    case Quantity::Parameter: return "parameter";
  }
  return "?";
}

/// Where the first non-finite value appeared. `step` is the time index n of the state x_n,
/// control c_n or adjoint λ_n; for a Gradient or a Parameter it is -1 and `sample` is the
/// parameter index.
struct NonFinite {
  Quantity quantity = Quantity::Loss;
  Index step = -1;
  Index sample = -1;
  double value = 0;
};

/// Diagnostics of one reverse sweep.
struct SweepDiagnostics {
  double grad_norm2 = 0;                    ///< ‖g‖²
  std::vector<double> adjoint_norms;        ///< ‖λ_n‖_F of the batch adjoint, n = 0..m
  std::optional<NonFinite> first_non_finite;  ///< first NaN/Inf of the sweep, if any
  bool params_overlapped = false;  ///< parameter products ran on a second thread (speed only)
};

/// Diagnostics comparing the modified vector g_M with the regular gradient g_R.
struct ComparisonDiagnostics {
  /// cos(g_M, g_R) in [-1, 1]; 0 when either is zero or not finite
  double cos_modified_regular = 0;
  double agree_fraction = 0;  ///< `sign_agreement(g_M, g_R)` (core/sign.hpp)
};


namespace detail {

/// cos(a, b) of vectors of n entries, summed in double over a / max|a| and b / max|b|, so that
/// no finite input overflows or underflows; 0 when either is zero or not finite (a sweep
/// reports that as its first non-finite value).
template <class Scalar>
[[nodiscard]] double scaled_cosine(const Scalar* a, const Scalar* b, Index n) {
  double a_max = 0, b_max = 0;
  for (Index i = 0; i < n; ++i) {
    a_max = std::max(a_max, std::abs(static_cast<double>(a[i])));
    b_max = std::max(b_max, std::abs(static_cast<double>(b[i])));
    if (!finite_by_bits(a[i]) || !finite_by_bits(b[i])) return 0.0;
  }
  if (a_max == 0 || b_max == 0) return 0.0;
  double dot = 0, aa = 0, bb = 0;
  for (Index i = 0; i < n; ++i) {
    const double x = static_cast<double>(a[i]) / a_max, y = static_cast<double>(b[i]) / b_max;
    dot += x * y;
    aa += x * x;
    bb += y * y;
  }
  return dot / (std::sqrt(aa) * std::sqrt(bb));
}

/// `compare`, writing the combined vector to `combined` (n entries) in the same pass unless it
/// is null.
template <class Scalar>
[[nodiscard]] ComparisonDiagnostics compare_in_pass(const Vector<Scalar>& modified,
                                                    const Vector<Scalar>& regular,
                                                    Scalar* combined) {
  PairSums<Scalar> sums;
  constexpr bool one_pass = pair_sums_in_registers<Scalar>;
  const Index agreeing = agreement_pass<Scalar>(modified.data(), regular.data(), modified.size(),
                                                combined, one_pass ? &sums : nullptr);
  if constexpr (!one_pass) {
    sums.dot = modified.dot(regular);
    sums.modified_norm2 = modified.squaredNorm();
    sums.regular_norm2 = regular.squaredNorm();
  }
  ComparisonDiagnostics result;
  const double norms = static_cast<double>(std::sqrt(sums.modified_norm2) *
                                           std::sqrt(sums.regular_norm2));
  // Squares of exploding (or vanishing) gradients leave the scalar's range: Inf made the
  // cosine NaN, zero made it 0 for equal vectors. Such sums are redone with scaled vectors.
  const auto in_range = [](Scalar norm2) {
    return finite_by_bits(norm2) && norm2 >= std::numeric_limits<Scalar>::min();
  };
  if (in_range(sums.modified_norm2) && in_range(sums.regular_norm2) && finite_by_bits(sums.dot) &&
      finite_by_bits(norms))
    result.cos_modified_regular = static_cast<double>(sums.dot) / norms;
  else
    result.cos_modified_regular = scaled_cosine(modified.data(), regular.data(), modified.size());
  // The quotient of parallel vectors rounds past ±1 (by up to 1.2e-7 in float).
  result.cos_modified_regular = std::clamp(result.cos_modified_regular, -1.0, 1.0);
  result.agree_fraction =
      static_cast<double>(agreement_fraction<Scalar>(agreeing, modified.size()));
  return result;
}

}  // namespace detail

/// cos(g_M, g_R) and the sign-agreement fraction of `sign_agreement` (core/sign.hpp: sign(0) =
/// 0, NaN never agrees, 1 for empty vectors) of g_M and g_R (size n each).
template <class Scalar>
[[nodiscard]] ComparisonDiagnostics compare(const Vector<Scalar>& modified,
                                            const Vector<Scalar>& regular) {
  detail::require_same_size(modified, regular, "compare");
  return detail::compare_in_pass<Scalar>(modified, regular, nullptr);
}

/// `compare`, and `combined` = combine(g_M, g_R) (optim/combined_update.hpp; resized to n)
/// from the same pass over both vectors: a pass of its own costs as much as reading them
/// (guidance's 13,004 floats: 2.0 µs, docs/benchmark-runs-zen4.md, thirty-third run).
template <class Scalar>
[[nodiscard]] ComparisonDiagnostics compare_and_combine(const Vector<Scalar>& modified,
                                                        const Vector<Scalar>& regular,
                                                        Vector<Scalar>& combined) {
  detail::require_same_size(modified, regular, "compare_and_combine");
  detail::require(&combined != &modified && &combined != &regular,
                  "compare_and_combine: combined is g_M or g_R; expected a vector of its own");
  combined.resize(modified.size());
  return detail::compare_in_pass<Scalar>(modified, regular, combined.data());
}

/// Loss and both vectors the combined update needs, from one forward pass.
template <class Scalar>
struct GradientPair {
  Scalar loss = 0;
  Vector<Scalar> regular;   ///< g_R, the true gradient (Full)
  Vector<Scalar> modified;  ///< g_M, gradient stopped at the network input (PhysicsOnly)
  Vector<Scalar> combined;  ///< g_C = combine(g_M, g_R), formed in `comparison`'s pass
  SweepDiagnostics regular_diagnostics;
  SweepDiagnostics modified_diagnostics;
  ComparisonDiagnostics comparison;
  std::optional<NonFinite> forward_non_finite;
};

}  // namespace sbptt
