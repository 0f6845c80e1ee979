#pragma once
/// \file sin and cos of one angle together: for a scalar, for a block of SIMD lanes of floats
/// (Eigen's vectorised sin and cos) and for a block of doubles, which Eigen 3.4 does not
/// vectorise (it calls std::sin and std::cos lane by lane) and which is computed here in
/// registers:
///
///     x = n π/2 + r,   n = round(2x / π),   r ∈ [−π/4, π/4],
///     sin r = r + r z S(z),   cos r = 1 − z/2 + z² C(z),   z = r²,
///     (sin x, cos x) = (sin r, cos r), (cos r, −sin r), (−sin r, −cos r), (−cos r, sin r)
///                      for n mod 4 = 0, 1, 2, 3.
///
/// S and C are the degree-5 polynomials of Cephes' `sin` and `cos` (S. L. Moshier). π/2 enters
/// in fdlibm's four parts, the first three with at most 32 significant bits: for |n| < 2^20
/// their products with n are exact, and r is correct to rounding even where x is closest to a
/// multiple of π/2 (with three parts, the missing 8.5e-32·|n| made sin(50π) 43 ulp off).
/// Lanes with |x| > 10^6 (a margin below |n| = 2^20) take std::sin and std::cos, each lane by
/// itself, so that no lane's result depends on the others; ±0 keeps its sign in sin, and NaN
/// and ±∞ give NaN. Within 2 ulp of std::sin and std::cos over the test's grid and random
/// arguments, with and without fused multiply-adds (tests/test_core_sine_cosine.cpp; the three
/// roundings of r can add up to about 1.5 ulp of a small sin x). Like the tanh, it relies on
/// rounding by adding 1.5·2^52 (core/round_to_integer.hpp): not for -ffast-math.
#include <cmath>

#include <Eigen/Core>

#include "sbptt/core/round_to_integer.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// sin and cos of every lane of a register of doubles (see the file comment).
template <class Packet>
SBPTT_ALWAYS_INLINE inline void sine_cosine_packet_double(const Packet& x, Packet& sine,
                                                          Packet& cosine) {
  using namespace Eigen::internal;
  constexpr double two_over_pi = 6.36619772367581382433e-01;
  constexpr double half_pi_1 = 1.57079632673412561417e+00;  // fdlibm's pio2_1, pio2_2,
  constexpr double half_pi_2 = 6.07710050630396597660e-11;  // pio2_3 and pio2_3t
  constexpr double half_pi_3 = 2.02226624871116645580e-21;
  constexpr double half_pi_4 = 8.47842766036889956997e-32;
  constexpr double largest_reduced = 1e6;
  constexpr double sine_series[] = {1.58962301576546568060e-10, -2.50507477628578072866e-8,
                                    2.75573136213857245213e-6,  -1.98412698295895385996e-4,
                                    8.33333333332211858878e-3,  -1.66666666666666307295e-1};
  constexpr double cosine_series[] = {-1.13585365213876817300e-11, 2.08757008419747316778e-9,
                                      -2.75573141792967388112e-7,  2.48015872888517045348e-5,
                                      -1.38888888888730564116e-3,  4.16666666666665929218e-2};
  const Packet rounding = pset1<Packet>(round_to_integer_shift);
  const Packet n = psub(pmadd(x, pset1<Packet>(two_over_pi), rounding), rounding);
  Packet r = psub(x, pmul(n, pset1<Packet>(half_pi_1)));
  r = psub(r, pmul(n, pset1<Packet>(half_pi_2)));
  r = psub(r, pmul(n, pset1<Packet>(half_pi_3)));
  r = psub(r, pmul(n, pset1<Packet>(half_pi_4)));
  const Packet z = pmul(r, r);
  Packet s = pset1<Packet>(sine_series[0]);
  Packet c = pset1<Packet>(cosine_series[0]);
  for (int i = 1; i < 6; ++i) {
    s = pmadd(s, z, pset1<Packet>(sine_series[i]));
    c = pmadd(c, z, pset1<Packet>(cosine_series[i]));
  }
  s = pmadd(pmul(r, z), s, r);
  // 1 − z/2 + z² C(z) with the rounding error of 1 − z/2 added back (fdlibm's cos kernel):
  // summed plainly, without fused multiply-adds it was 2 ulp off std::cos at x = 16.4625.
  const Packet one = pset1<Packet>(1.0);
  const Packet half_z = pmul(z, pset1<Packet>(0.5));
  const Packet head = psub(one, half_z);
  c = padd(head, pmadd(pmul(z, z), c, psub(psub(one, head), half_z)));

  // n mod 4 = m, exactly, from n's value: odd m swaps the two; m ≥ 2 negates the sine, m = 1
  // or 2 the cosine.
  const Packet m = psub(n, pmul(pset1<Packet>(4.0), pfloor(pmul(n, pset1<Packet>(0.25)))));
  const Packet odd = pcmp_eq(pabs(psub(m, pset1<Packet>(2.0))), one);
  const Packet sign_bit = pset1<Packet>(-0.0);
  const Packet negate_sine = pand(pcmp_le(pset1<Packet>(2.0), m), sign_bit);
  const Packet negate_cosine =
      pand(pcmp_lt(pabs(psub(m, pset1<Packet>(1.5))), one), sign_bit);
  sine = pxor(pselect(odd, c, s), negate_sine);
  cosine = pxor(pselect(odd, s, c), negate_cosine);
  sine = pselect(pcmp_eq(x, pzero(x)), x, sine);  // sin(±0) = ±0

  // False for NaN, which the reduction already carries through.
  if (predux_any(pcmp_lt(pset1<Packet>(largest_reduced), pabs(x)))) {
    constexpr int lanes = unpacket_traits<Packet>::size;
    double xs[lanes], sines[lanes], cosines[lanes];
    pstoreu(xs, x);
    pstoreu(sines, sine);
    pstoreu(cosines, cosine);
    for (int l = 0; l < lanes; ++l) {
      if (!(std::abs(xs[l]) > largest_reduced)) continue;
      sines[l] = std::sin(xs[l]);
      cosines[l] = std::cos(xs[l]);
    }
    sine = ploadu<Packet>(sines);
    cosine = ploadu<Packet>(cosines);
  }
}

/// sin and cos of one number: std::sin and std::cos, or those of the number type (found by
/// argument-dependent lookup: Eigen's AutoDiffScalar has its own).
template <class Scalar>
void sine_cosine(const Scalar& x, Scalar& sine, Scalar& cosine) {
  using std::cos, std::sin;
  sine = sin(x);
  cosine = cos(x);
}

/// sin and cos of a block of floats: Eigen's vectorised ones.
template <int Lanes>
void sine_cosine(const Eigen::Array<float, Lanes, 1>& x, Eigen::Array<float, Lanes, 1>& sine,
                 Eigen::Array<float, Lanes, 1>& cosine) {
  sine = x.sin();
  cosine = x.cos();
}

/// sin and cos of a block of doubles, a register at a time (`sine_cosine_packet_double`).
template <int Lanes>
void sine_cosine(const Eigen::Array<double, Lanes, 1>& x, Eigen::Array<double, Lanes, 1>& sine,
                 Eigen::Array<double, Lanes, 1>& cosine) {
  using Packet = typename Eigen::internal::packet_traits<double>::type;
  constexpr int packet_lanes = Eigen::internal::packet_traits<double>::size;
  static_assert(Lanes % packet_lanes == 0, "a block of doubles is whole registers");
  for (int i = 0; i < Lanes; i += packet_lanes) {
    Packet s, c;
    sine_cosine_packet_double(Eigen::internal::ploadu<Packet>(x.data() + i), s, c);
    Eigen::internal::pstoreu(sine.data() + i, s);
    Eigen::internal::pstoreu(cosine.data() + i, c);
  }
}

}  // namespace sbptt::detail
