#pragma once
/// \file Loops over arrays of SIMD registers, written out at compile time. Such an array is
/// indexed by loop counters whose bounds are template arguments; only where every index is a
/// constant can the compiler keep it in registers. GCC 12 unrolls those loops by itself at -O3
/// but not at -O2 (CMake's RelWithDebInfo, Debian's own builds), where the arrays lived on the
/// stack. Two tools (AVX-512 code, docs/benchmark-runs.md, sixteenth and seventeenth runs):
/// - `SBPTT_UNROLL` unrolls the loop after it completely. The parameter products' kernel
///   (nn/outer_product.hpp) uses it: 100 × 100 × 8 at -O2 took 3209–3274 ns without it,
///   740–744 with it; `static_for` there, its lambdas nested three deep not all inlined,
///   2358–2385 at -O2 and 1396–1410 at -O3. So do the short products' dot products
///   (`PackedMatrix::row_dots`; `static_for` was not measured there).
/// - `static_for` calls f(0), …, f(N − 1) with constant indices. The packed product's blocks
///   use it: guidance's R epoch at -O2 took 27.4–27.8 ms with plain loops, 16.4–16.7 with it.
///   `SBPTT_UNROLL` on those loops made the -O3 code of 4-column blocks take 1.5 times as
///   long (385–392 → 578–608 ns).
#include <type_traits>
#include <utility>

#if defined(__clang__)
#define SBPTT_UNROLL _Pragma("unroll")
#elif defined(__GNUC__)
#define SBPTT_UNROLL _Pragma("GCC unroll 64")
#else
#define SBPTT_UNROLL
#endif

// Inline the calls of a function (in front of it) or of a lambda (after its parameters) even
// where the compiler would not: clang 14 at -O1 under the sanitizers ran the packed product
// 4.5 times slower through `static_for` without it.
#if defined(__GNUC__) || defined(__clang__)
#define SBPTT_ALWAYS_INLINE __attribute__((always_inline))
#else
#define SBPTT_ALWAYS_INLINE
#endif

// One machine copy of a function for all its callers: never inlined and, with GCC, never
// cloned either (`noipa`: with `noinline` alone, constant propagation may still compile a copy
// for a caller's constant argument). Two paths that must give the same bits (a batch whole and
// in parts, one thread and several) call the arithmetic they share through such a function;
// inlined into each, GCC vectorised and contracted the copies differently (docs/design.md,
// "One machine copy of each per-sample computation").
#if defined(__GNUC__) && !defined(__clang__)
#define SBPTT_ONE_COPY __attribute__((noinline, noipa))
#elif defined(__clang__)
#define SBPTT_ONE_COPY __attribute__((noinline))
#else
#define SBPTT_ONE_COPY
#endif

namespace sbptt::detail {

/// f(std::integral_constant<int, 0>{}), …, f(std::integral_constant<int, N − 1>{}), in order.
/// Pass lambdas marked SBPTT_ALWAYS_INLINE.
template <int N, class F>
SBPTT_ALWAYS_INLINE inline void static_for(F&& f) {
  [&]<int... I>(std::integer_sequence<int, I...>) SBPTT_ALWAYS_INLINE {
    (f(std::integral_constant<int, I>{}), ...);
  }(std::make_integer_sequence<int, N>{});
}

}  // namespace sbptt::detail
