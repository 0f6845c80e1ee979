#pragma once
/// \file Element-wise activations of the layers: identity and tanh.
///
/// Backward passes take the derivative from the stored layer *output* y rather than the
/// pre-activation z: for tanh, f'(z) = 1 − y², so the workspace needs to keep only y and no
/// second buffer per layer.
#include <algorithm>
#include <cmath>
#include <string_view>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/nn/tanh_double.hpp"

namespace sbptt {

/// The activation applied after a layer's affine map.
enum class Activation {
  Identity,  ///< f(z) = z (the usual output layer of a controller)
  Tanh,      ///< f(z) = tanh z
};

/// Lower-case name, as used in error messages and `describe()` strings.
[[nodiscard]] constexpr std::string_view to_string(Activation activation) {
  switch (activation) {
    case Activation::Identity: return "identity";
    case Activation::Tanh: return "tanh";
  }
  return "unknown";
}

/// f(z) for one scalar.
template <class Scalar>
[[nodiscard]] Scalar activate(Activation activation, Scalar z) {
  return activation == Activation::Tanh ? std::tanh(z) : z;
}

/// f'(z) expressed through the output y = f(z): 1 for identity, 1 − y² for tanh.
template <class Scalar>
[[nodiscard]] Scalar activation_derivative_from_output(Activation activation, Scalar y) {
  return activation == Activation::Tanh ? Scalar(1) - y * y : Scalar(1);
}

namespace detail {

/// tanh of the `registers` × `Lanes` entries at `z`, one SIMD register's worth at a time.
/// One machine copy (SBPTT_ONE_COPY), so that every entry of every call runs the same code.
template <class Scalar, int Lanes>
SBPTT_ONE_COPY void tanh_registers(Scalar* z, Index registers) {
  for (Index r = 0; r < registers; ++r) {
    Scalar* entries = z + r * Lanes;
    if constexpr (std::is_same_v<Scalar, double>) {
      using Packet = typename Eigen::internal::packet_traits<double>::type;
      Eigen::internal::pstoreu(entries,
                               tanh_packet_double(Eigen::internal::ploadu<Packet>(entries)));
    } else {
      Eigen::Map<Eigen::Array<Scalar, Lanes, 1>> block(entries);
      block = block.tanh();
    }
  }
}

}  // namespace detail

/// Applies f in place to the `size` entries at `z`; identity is a no-op. For double the tanh is
/// `detail::tanh_packet_double` (tanh_double.hpp), for float Eigen's own. Every entry goes through
/// the same code, in whole registers (the last one padded), whatever its place. A dynamic Eigen
/// loop takes the entries before the first aligned address and after the last whole register one by
/// one, in scalar code compiled apart, where the compiler is free to fuse multiply-adds
/// differently; then a sample's outputs could depend on the columns evaluated beside it, which the
/// engine's forward pass in parts must exclude (with GCC 12 the two paths measured equal).
template <class Scalar>
void activate_in_place(Activation activation, Scalar* z, Index size) {
  if (activation != Activation::Tanh) return;
  constexpr int lanes = Eigen::internal::packet_traits<Scalar>::size;
  const Index whole = size / lanes;
  detail::tanh_registers<Scalar, lanes>(z, whole);
  const Index i = whole * lanes;
  if (i == size) return;
  alignas(64) Scalar tail[lanes] = {};
  std::copy(z + i, z + size, tail);
  detail::tanh_registers<Scalar, lanes>(tail, 1);
  std::copy(tail, tail + (size - i), z + i);
}

/// The same for every entry of a contiguous matrix or array `z` (any shape).
template <class Derived>
void activate_in_place(Activation activation, Eigen::PlainObjectBase<Derived>& z) {
  activate_in_place(activation, z.data(), z.size());
}

/// `delta = upstream ⊙ f'(z)`, with f' taken from the layer output `y` (f(z)).
/// \param y         layer output, rows × B
/// \param upstream  adjoint of the layer output ∂L/∂y, rows × B
/// \param delta     adjoint of the pre-activation ∂L/∂z, rows × B (may alias `upstream`, as
///                  the expression is element-wise)
template <class DerivedY, class DerivedUp, class DerivedDelta>
void activation_backward(Activation activation, const Eigen::DenseBase<DerivedY>& y,
                         const Eigen::DenseBase<DerivedUp>& upstream,
                         Eigen::DenseBase<DerivedDelta>& delta) {
  using Scalar = typename DerivedDelta::Scalar;
  if (activation == Activation::Tanh) {
    delta.derived().array() =
        upstream.derived().array() * (Scalar(1) - y.derived().array().square());
  } else {
    delta.derived() = upstream.derived();
  }
}

namespace detail {

/// Read-only view of a column-major block of memory; the layers see every batch and every
/// slice of the flat parameter vector through these, so that nothing is copied.
template <class Scalar>
using ConstMatrixMap = Eigen::Map<const Matrix<Scalar>>;

/// Writable column-major view (see `ConstMatrixMap`).
template <class Scalar>
using MatrixMap = Eigen::Map<Matrix<Scalar>>;

/// Read-only row-major view: weights are row-major inside the flat parameter vector.
template <class Scalar>
using ConstRowMajorMap = Eigen::Map<const RowMajorMatrix<Scalar>>;

/// Writable row-major view (the weight part of a gradient vector).
template <class Scalar>
using RowMajorMap = Eigen::Map<RowMajorMatrix<Scalar>>;

/// A rows × cols view over `storage`, growing it only when it is too small, so that a
/// scratch buffer reused across calls (and across networks) stops allocating after warm-up.
template <class Scalar>
[[nodiscard]] MatrixMap<Scalar> grow_map(Vector<Scalar>& storage, Index rows, Index cols) {
  if (storage.size() < rows * cols) storage.resize(rows * cols);
  return MatrixMap<Scalar>(storage.data(), rows, cols);
}

}  // namespace detail
}  // namespace sbptt
