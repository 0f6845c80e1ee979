#pragma once
// The second-order model of the compile-fail cases with hand-written a-Jacobians: a spring,
// x = (q, v), a = −q + u; each case adds its own (wrong) Jacobian member.
#include <sbptt/sbptt.hpp>

struct SpringAcceleration {
  static constexpr int kStateSize = 2, kControlSize = 1;
  template <class T>
  void acceleration(const sbptt::ColumnOf<T, 2>& x, const sbptt::ColumnOf<T, 1>& u,
                    sbptt::ColumnOf<T, 1>& a) const {
    a(0) = -x(0) + u(0);
  }
};
