#pragma once
/// \file One scalar multiply-add, rounded as the register kernels round theirs.
#include <cmath>

#include <Eigen/Core>

namespace sbptt::detail {

/// a·b + c rounded once where the target has a hardware FMA (x86 with FMA, ARM, POWER), as
/// the register code of the packed and outer products computes it; rounded twice elsewhere,
/// where the compiler cannot contract either and std::fma would be a slow library call.
template <class Scalar>
Scalar fused_multiply_add(Scalar a, Scalar b, Scalar c) {
#if defined(EIGEN_VECTORIZE_FMA) || defined(__FP_FAST_FMA) || defined(__FP_FAST_FMAF) || \
    defined(__ARM_FEATURE_FMA)
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}

}  // namespace sbptt::detail
