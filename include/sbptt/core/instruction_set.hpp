#pragma once
/// \file The SIMD instruction set a translation unit was compiled for, named from the
/// compiler's predefined macros.
///
/// Eigen vectorises with the widest set the compiler enables (`-march=native`, `-mavx2 -mfma`,
/// ...), and the speed of every product in sbptt follows: on an AVX-512 core a build without
/// `-march` runs SSE2 code at about half the speed. Programs that print timings state this name
/// beside them, so that no figure is quoted without the code it measured. The name describes
/// the code, not the machine it runs on.
namespace sbptt {

/// "AVX-512", "AVX2+FMA", "AVX2", "AVX", "SSE4.2", "SSE2", "SVE", "NEON" or "scalar": the widest
/// vector instruction set this translation unit may use. AVX-512 implies its own FMA.
[[nodiscard]] constexpr const char* instruction_set() {
#if defined(__AVX512F__)
  return "AVX-512";
#elif defined(__AVX2__) && defined(__FMA__)
  return "AVX2+FMA";
#elif defined(__AVX2__)
  return "AVX2";
#elif defined(__AVX__)
  return "AVX";
#elif defined(__SSE4_2__)
  return "SSE4.2";
#elif defined(__SSE2__) || defined(_M_X64)
  return "SSE2";
#elif defined(__ARM_FEATURE_SVE)
  return "SVE";
#elif defined(__ARM_NEON)
  return "NEON";
#else
  return "scalar";
#endif
}

}  // namespace sbptt
