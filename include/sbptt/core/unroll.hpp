#pragma once
/// \file Loops over arrays of SIMD registers, written out at compile time. Such an array is
/// indexed by loop counters whose bounds are template arguments; only where every index is a
/// constant can the compiler keep it in registers. GCC 12 unrolls those loops by itself at -O3
/// but not at -O2 (CMake's RelWithDebInfo, Debian's own builds), where the arrays lived on the
/// stack. Two tools, each where it measured faster (AVX-512 code, docs/benchmark-runs.md,
/// sixteenth and seventeenth runs):
/// - `SBPTT_UNROLL` unrolls the loop after it completely (the parameter products' kernel,
///   nn/outer_product.hpp: 100 × 100 × 8 at -O2 3209–3274 ns without it, 740–744 with it;
///   the short products' dot products). On the packed product's blocks it slowed the -O3
///   code of 4-column blocks by half.
/// - `static_for` calls f(0), …, f(N − 1) with constant indices (the packed product's blocks,
///   nn/packed_product.hpp: guidance's R epoch at -O2 27.2 ms with loops, 17.1 with it).
///   In the parameter products' kernel, its lambdas nested three deep were not all inlined:
///   100 × 100 × 8 took 2358–2385 ns at -O2 and 1396–1410 at -O3, against 723–733.
#include <type_traits>
#include <utility>

#if defined(__clang__)
#define SBPTT_UNROLL _Pragma("unroll")
#elif defined(__GNUC__)
#define SBPTT_UNROLL _Pragma("GCC unroll 64")
#else
#define SBPTT_UNROLL
#endif

// After a lambda's parameters: inline its calls even where the compiler would not (clang 14
// at -O1 under the sanitizers ran the packed product 4.5 times slower through `static_for`
// without it).
#if defined(__GNUC__) || defined(__clang__)
#define SBPTT_ALWAYS_INLINE __attribute__((always_inline))
#else
#define SBPTT_ALWAYS_INLINE
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
