#pragma once
/// \file The temporaries of `Network`: its packed weights when none are given and its backward
/// pass's layer adjoints. Thread-local for `backward`, because it takes the workspace `const`
/// and may run on several threads at once (network.hpp); `backward_inputs` keeps the same
/// buffers in the caller's `LayerAdjoints` instead, so that a caller moving between threads
/// does not grow a new set on each. The buffers only grow, so nothing is allocated after the
/// first call at a shape.
#include <cstddef>
#include <vector>

#include "sbptt/core/types.hpp"
#include "sbptt/nn/packed_product.hpp"

namespace sbptt {

namespace detail {

/// Temporaries of `Network`'s backward pass: a thread's for `backward`, a `LayerAdjoints`'
/// for `backward_inputs` (see the file comment for why).
template <class Scalar>
struct NetworkScratch {
  Vector<Scalar> adjoint;  ///< input adjoint of a layer with an activation, before f'
  Vector<Scalar> columns;  ///< conv window adjoints (im2col shape)
  std::vector<Vector<Scalar>> deltas;  ///< Δ of every layer, for the plain `backward`
};

/// Packed W (with b) and Wᵀ of the first `count` layers. The vectors only grow, so that the
/// per-thread scratch serves networks of several shapes in turn without allocating.
template <class Scalar>
struct PackedLayers {
  std::size_t count = 0;
  std::vector<PackedMatrix<Scalar>> weights;
  std::vector<PackedMatrix<Scalar>> transposed;
};

/// What the overloads without packed weights pack into, one per thread.
template <class Scalar>
[[nodiscard]] PackedLayers<Scalar>& packed_scratch() {
  thread_local PackedLayers<Scalar> packed;
  return packed;
}

template <class Scalar>
[[nodiscard]] NetworkScratch<Scalar>& network_scratch() {
  thread_local NetworkScratch<Scalar> scratch;
  return scratch;
}

}  // namespace detail

}  // namespace sbptt
