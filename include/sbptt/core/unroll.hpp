#pragma once
/// \file SBPTT_UNROLL: unroll the loop after it completely. The parameter products' register
/// kernel (nn/outer_product.hpp) keeps arrays of SIMD registers indexed by loop counters whose
/// bounds are template arguments; only in fully unrolled loops can the compiler keep them in
/// registers. GCC 12 unrolls them by itself at -O3 but not at -O2 (CMake's RelWithDebInfo,
/// Debian's own builds), where they lived on the stack: the 100 × 100 × 8 product took 3209–
/// 3274 ns instead of 740–744 (AVX-512 code, docs/benchmark-runs.md, sixteenth run).
#if defined(__clang__)
#define SBPTT_UNROLL _Pragma("unroll")
#elif defined(__GNUC__)
#define SBPTT_UNROLL _Pragma("GCC unroll 64")
#else
#define SBPTT_UNROLL
#endif
