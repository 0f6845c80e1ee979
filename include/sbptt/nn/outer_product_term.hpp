#pragma once
/// \file One term D diag(s) Xᵀ of a parameter product (outer_product.hpp): a step's samples.
#include "sbptt/core/types.hpp"

namespace sbptt {

/// D (rows × n, column-major) diag(s) Xᵀ (X: cols × n, column-major); `scale` holds s (n
/// entries), or is null for s = 1. The terms of several steps of a sweep are added in one
/// call (`add_outer_products`), each entry in their order, as one call per term would.
template <class Scalar>
struct OuterProductTerm {
  const Scalar* d;
  const Scalar* x;
  Index n;
  const Scalar* scale = nullptr;
};

}  // namespace sbptt
