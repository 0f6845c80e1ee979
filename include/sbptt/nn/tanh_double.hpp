#pragma once
/// \file tanh of doubles in SIMD registers.
///
/// Eigen 3.4 vectorises tanh for float only; for double it calls std::tanh per entry (≈ 20 ns
/// each, which made tanh the largest cost of a double MLP epoch). `tanh_packet_double` takes a
/// register of doubles x, and with a = |x|, t = min(2a, 40) computes
///
///     tanh a = (e^t − 1) / (e^t − 1 + 2),      e^t − 1 = 2^k (e^r − 1) + (2^k − 1),
///     k = round(t / ln 2),   r = t − k ln 2 ∈ [−ln2/2, ln2/2],
///     e^r − 1 = r (1 + r/2! + r²/3! + … + r¹²/13!)      (Taylor; the rest < 0.35¹⁴/14! < 5e-18)
///
/// and gives the result the sign of x (so tanh(−0) = −0). e^r − 1 is summed without forming
/// e^r first, so that small arguments keep their relative accuracy (k = 0: the numerator is
/// r times the series). ln 2 enters in two parts, the first with few enough bits that k times
/// it is exact, so r is exact to one rounding with or without fused multiply-adds. t stops at
/// 40: tanh rounds to 1 from a ≈ 19.06 on, and 2^k stays a normal number. NaN stays NaN.
///
/// The cost is one division and about 28 other instructions per register, with no branch and
/// no `select`; the same code runs for 2, 4 or 8 lanes and for a lone double (a build without
/// SIMD). It stays within 1e-15 relative of std::tanh (tests/test_nn_dense.cpp; 6.3e-16 at
/// worst at a million random arguments, where std::tanh is itself up to 3e-16 off a
/// long-double tanh). It rounds by adding 1.5·2^52 (core/round_to_integer.hpp): not for
/// -ffast-math.
#include <bit>
#include <cstdint>

#include <Eigen/Core>

#include "sbptt/core/round_to_integer.hpp"
#include "sbptt/core/unroll.hpp"

namespace sbptt::detail {

/// `power_of_two(biased, k)` = 2^k for integers k ∈ [−1022, 1023] (in doubles), where `biased`
/// = k + 1023 + 1.5·2^52 exactly: the low bits of biased's mantissa are k + 1023, and a 64-bit
/// shift by 52 moves them into the exponent field. This is the portable form, Eigen's `pldexp`
/// (for registers of the instruction sets the overloads below do not cover); the overloads do
/// the shift.
template <class Packet>
[[nodiscard]] Packet power_of_two_portable(const Packet& /*biased*/, const Packet& k) {
  return Eigen::internal::pldexp(Eigen::internal::pset1<Packet>(1.0), k);
}

template <class Packet>
[[nodiscard]] Packet power_of_two(const Packet& biased, const Packet& k) {
  return power_of_two_portable(biased, k);
}

// Declared before `tanh_packet_double`: Eigen's packets are built-in vector types, which have
// no namespace in which argument-dependent lookup could find a later overload.

/// A lone double (a build without SIMD): the same shift. Eigen's scalar `pldexp` converts k to
/// int, which is undefined behaviour for the NaN that a NaN argument of the tanh makes of k.
[[nodiscard]] inline double power_of_two(const double& biased, const double& /*k*/) {
  return std::bit_cast<double>(std::bit_cast<std::uint64_t>(biased) << 52);
}
#if defined(EIGEN_VECTORIZE_AVX512)
[[nodiscard]] inline Eigen::internal::Packet8d power_of_two(
    const Eigen::internal::Packet8d& biased, const Eigen::internal::Packet8d& /*k*/) {
  return _mm512_castsi512_pd(_mm512_slli_epi64(_mm512_castpd_si512(biased), 52));
}
#endif
#if defined(EIGEN_VECTORIZE_AVX2)
[[nodiscard]] inline Eigen::internal::Packet4d power_of_two(
    const Eigen::internal::Packet4d& biased, const Eigen::internal::Packet4d& /*k*/) {
  return _mm256_castsi256_pd(_mm256_slli_epi64(_mm256_castpd_si256(biased), 52));
}
#endif
#if defined(EIGEN_VECTORIZE_SSE2)
[[nodiscard]] inline Eigen::internal::Packet2d power_of_two(
    const Eigen::internal::Packet2d& biased, const Eigen::internal::Packet2d& /*k*/) {
  return _mm_castsi128_pd(_mm_slli_epi64(_mm_castpd_si128(biased), 52));
}
#endif

/// tanh of every lane of `x` (see the file comment). Inlined, so that a loop over registers
/// keeps the constants in registers.
template <class Packet>
[[nodiscard]] SBPTT_ALWAYS_INLINE inline Packet tanh_packet_double(const Packet& x) {
  using namespace Eigen::internal;
  constexpr double ln2_head = 0.693145751953125;  // 16 bits: k·ln2_head is exact
  constexpr double ln2_tail = 1.42860682030941723212e-6;
  constexpr double log2_e = 1.4426950408889634074;
  // 1/n! for n = 13, 12, …, 2, the series of (e^r − 1)/r from its last term.
  constexpr double series[] = {1.0 / 6227020800.0, 1.0 / 479001600.0, 1.0 / 39916800.0,
                               1.0 / 3628800.0,    1.0 / 362880.0,    1.0 / 40320.0,
                               1.0 / 5040.0,       1.0 / 720.0,       1.0 / 120.0,
                               1.0 / 24.0,         1.0 / 6.0,         0.5};
  const Packet one = pset1<Packet>(1.0);
  const Packet sign = pand(x, pset1<Packet>(-0.0));
  const Packet a = pabs(x);
  // NaN stays NaN through this min (Eigen's pmin returns its first argument then).
  const Packet t = pmin(padd(a, a), pset1<Packet>(40.0));
  const Packet rounding = pset1<Packet>(round_to_integer_shift);
  const Packet shifted = pmadd(t, pset1<Packet>(log2_e), rounding);
  const Packet k = psub(shifted, rounding);
  const Packet r =
      pmadd(k, pset1<Packet>(-ln2_tail), pmadd(k, pset1<Packet>(-ln2_head), t));
  Packet sum = pset1<Packet>(series[0]);
  for (int n = 1; n < 12; ++n) sum = pmadd(sum, r, pset1<Packet>(series[n]));
  const Packet exp_r_minus_one = pmul(pmadd(sum, r, one), r);
  const Packet scale = power_of_two(padd(shifted, pset1<Packet>(1023.0)), k);
  const Packet exp_t_minus_one = pmadd(scale, exp_r_minus_one, psub(scale, one));
  return por(pdiv(exp_t_minus_one, padd(exp_t_minus_one, pset1<Packet>(2.0))), sign);
}

}  // namespace sbptt::detail
