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

/// The constants of Cephes' tanh below.
struct CephesTanh {
  // P(s) = (p0·s + p1)·s + p2, Q(s) = ((s + q0)·s + q1)·s + q2.
  static constexpr double p0 = -9.64399179425052238628e-1, p1 = -9.92877231001918586564e1,
                          p2 = -1.61468768441708447952e3;
  static constexpr double q0 = 1.12811678491632931402e2, q1 = 2.23548839060100448583e3,
                          q2 = 4.84406305325125486048e3;
  /// Up to here x·(1 + s·P(s)/Q(s)), beyond it 1 − 2/(e^{2x} + 1).
  static constexpr double branch_point = 0.625;
};

/// Eigen 3.4 vectorises tanh for float only; for double it calls std::tanh per entry (≈ 20 ns
/// each, which made tanh the largest cost of a double MLP epoch). Both functions below are
/// Cephes' `tanh` (S. L. Moshier): x·(1 + s·P(s)/Q(s)), s = x², for |x| ≤ 0.625 (a product, so
/// that tanh(−0) = −0), and 1 − 2/(e^{2x} + 1) beyond (exactly ±1 for ±∞: e^{2x} is ∞, or so
/// small that 2/(e^{2x} + 1) rounds to 2); NaN stays NaN. Both are within 1e-15 relative of
/// std::tanh (test_nn_dense).
///
/// This one takes a register of doubles, evaluates both branches in it and picks one per lane
/// (`pselect`), with Eigen's vectorised exp. Where a register holds 4 or more doubles that is
/// faster than `tanh_entrywise_double`; with 2 it is slower (docs/benchmarks.md, "The double
/// tanh in registers").
template <class Packet>
[[nodiscard]] Packet tanh_packet_double(const Packet& x) {
  using Eigen::internal::pabs;
  using Eigen::internal::padd;
  using Eigen::internal::pcmp_lt;
  using Eigen::internal::pdiv;
  using Eigen::internal::pexp;
  using Eigen::internal::pmadd;
  using Eigen::internal::pmul;
  using Eigen::internal::pselect;
  using Eigen::internal::pset1;
  using Eigen::internal::psub;
  using C = CephesTanh;
  const Packet one = pset1<Packet>(1.0);
  const Packet s = pmul(x, x);
  const Packet p =
      pmadd(pmadd(pset1<Packet>(C::p0), s, pset1<Packet>(C::p1)), s, pset1<Packet>(C::p2));
  const Packet q = pmadd(pmadd(padd(s, pset1<Packet>(C::q0)), s, pset1<Packet>(C::q1)), s,
                         pset1<Packet>(C::q2));
  const Packet up_to_branch = pmul(x, pmadd(s, pdiv(p, q), one));
  const Packet past_branch = psub(one, pdiv(pset1<Packet>(2.0), padd(pexp(padd(x, x)), one)));
  const Packet is_past_branch = pcmp_lt(pset1<Packet>(C::branch_point), pabs(x));
  return pselect(is_past_branch, past_branch, up_to_branch);
}

/// The same with Eigen arrays, for builds whose registers hold fewer than 4 doubles: the pick
/// is a `select`, which Eigen 3.4 evaluates one entry at a time, so each entry computes only
/// its own branch, with libm's exp.
template <class Derived>
void tanh_entrywise_double(Eigen::ArrayBase<Derived>& z) {
  using C = CephesTanh;
  const auto& x = z.derived();
  const auto s = x.square();
  // P and Q inline: named as `auto` sub-expressions they measured 1.3 times slower (SSE2).
  z.derived() = (x.abs() > C::branch_point)
                    .select(1.0 - 2.0 / ((2.0 * x).exp() + 1.0),
                            x * (1.0 + s * (((C::p0 * s + C::p1) * s + C::p2) /
                                            (((s + C::q0) * s + C::q1) * s + C::q2))));
}

/// tanh of the `registers` × `Lanes` entries at `z`, one SIMD register's worth at a time.
/// One machine copy (SBPTT_ONE_COPY), so that every entry of every call runs the same code.
template <class Scalar, int Lanes>
SBPTT_ONE_COPY void tanh_registers(Scalar* z, Index registers) {
  for (Index r = 0; r < registers; ++r) {
    Scalar* entries = z + r * Lanes;
    if constexpr (std::is_same_v<Scalar, double> && Lanes >= 4) {
      using Packet = typename Eigen::internal::packet_traits<double>::type;
      Eigen::internal::pstoreu(entries,
                               tanh_packet_double(Eigen::internal::ploadu<Packet>(entries)));
    } else {
      Eigen::Map<Eigen::Array<Scalar, Lanes, 1>> block(entries);
      if constexpr (std::is_same_v<Scalar, double>) {
        tanh_entrywise_double(block);
      } else {
        block = block.tanh();
      }
    }
  }
}

}  // namespace detail

/// Applies f in place to the `size` entries at `z`; identity is a no-op. For double the tanh is
/// `detail::tanh_packet_double` (`detail::tanh_entrywise_double` where a register holds fewer
/// than 4 doubles), for float Eigen's own. Every entry goes through the same code, in whole
/// registers (the last one padded), whatever its place. A dynamic Eigen loop takes the entries
/// before the first aligned address and after the last whole register one by one, in scalar
/// code compiled apart, where the compiler is free to fuse multiply-adds differently; then a
/// sample's outputs could depend on the columns evaluated beside it, which the engine's
/// forward pass in parts must exclude (with GCC 12 the two paths measured equal).
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
