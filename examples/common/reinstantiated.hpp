#pragma once
// A shipped simulator seen as an `AutoDiffSimulator` model: its own `step`, instantiated once in
// the plain scalar and once in the dual numbers of the adapter. The tests use it to check every
// hand-written Jacobian and VJP against the automatic ones of the same step; bench uses it to
// price the adapter against the analytic VJP.
#include <type_traits>
#include <utility>

#include "sbptt/sim/autodiff.hpp"

namespace sbptt::examples {

/// `SimOf<T>` is the simulator in scalar T (an alias template such as
/// `template <class T> using CartPole4 = CartPole<T, 4>;`), built from the same arguments in
/// every scalar.
template <template <class> class SimOf, class Scalar = double>
struct Reinstantiated {
  static constexpr int kStateSize = SimOf<Scalar>::State::SizeAtCompileTime;
  static constexpr int kControlSize = SimOf<Scalar>::Control::SizeAtCompileTime;
  using DualScalar = Dual<Scalar, sum_or_dynamic(kStateSize, kControlSize)>;

  template <class... Args>
  explicit Reinstantiated(const Args&... args) : plain(args...), dual(args...) {}

  [[nodiscard]] Index state_dim() const { return plain.state_dim(); }
  [[nodiscard]] Index control_dim() const { return plain.control_dim(); }

  template <class T>
  void step(const ColumnOf<T, kStateSize>& x, const ColumnOf<T, kControlSize>& u,
            ColumnOf<T, kStateSize>& x_next) const {
    if constexpr (std::is_same_v<T, Scalar>) {
      plain.step(x, u, x_next);
    } else {
      dual.step(x, u, x_next);
    }
  }

  SimOf<Scalar> plain;
  SimOf<DualScalar> dual;
};

}  // namespace sbptt::examples
