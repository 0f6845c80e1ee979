// The instruction-set name printed beside every timing must describe the code that ran. Two
// truths independent of the header's own macro tests: the packet width Eigen vectorises with
// (with Eigen's FMA and AVX2 switches), and the running CPU (__builtin_cpu_supports), which
// must have every instruction the name claims, or the binary could not have run. A native build
// must use the widest set that CPU has.
#include <catch2/catch.hpp>

#include <Eigen/Core>
#include <string_view>

#include "sbptt/core/instruction_set.hpp"

namespace {

constexpr bool eigen_fma =
#ifdef EIGEN_VECTORIZE_FMA
    true;
#else
    false;
#endif

constexpr bool eigen_avx2 =
#ifdef EIGEN_VECTORIZE_AVX2
    true;
#else
    false;
#endif

}  // namespace

TEST_CASE("the instruction-set name matches the packet width Eigen vectorises with") {
  const std::string_view name = sbptt::instruction_set();
  const int floats_per_packet = Eigen::internal::packet_traits<float>::size;
  INFO("instruction set " << name << ", Eigen: " << Eigen::SimdInstructionSetsInUse() << ", "
                          << floats_per_packet << " floats per packet");
#if defined(__x86_64__) && !defined(EIGEN_DONT_VECTORIZE)
  if (name == "AVX-512") {
    CHECK(floats_per_packet == 16);
    CHECK(eigen_fma);
  } else if (name == "AVX2+FMA") {
    CHECK(floats_per_packet == 8);
    CHECK(eigen_fma);
    CHECK(eigen_avx2);
  } else if (name == "AVX2" || name == "AVX") {
    CHECK(floats_per_packet == 8);
    CHECK_FALSE(eigen_fma);
    CHECK(eigen_avx2 == (name == "AVX2"));
  } else {
    CHECK((name == "SSE2" || name == "SSE4.2"));
    CHECK(floats_per_packet == 4);
    CHECK_FALSE(eigen_fma);
  }
#else
  SUCCEED("not an x86-64 build with Eigen vectorisation: " << name);
#endif
}

TEST_CASE("the running CPU has every instruction the name claims") {
  const std::string_view name = sbptt::instruction_set();
  INFO("instruction set " << name);
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  CHECK(__builtin_cpu_supports("sse2"));
  if (name == "AVX-512") CHECK(__builtin_cpu_supports("avx512f"));
  if (name == "AVX2+FMA") CHECK((__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")));
  if (name == "AVX2") CHECK(__builtin_cpu_supports("avx2"));
  if (name == "AVX") CHECK(__builtin_cpu_supports("avx"));
  if (name == "SSE4.2") CHECK(__builtin_cpu_supports("sse4.2"));
#else
  SUCCEED("no __builtin_cpu_supports for this target: " << name);
#endif
}

TEST_CASE("a native build (SBPTT_NATIVE) uses the widest set the running CPU has") {
  const std::string_view name = sbptt::instruction_set();
  INFO("instruction set " << name);
#if SBPTT_NATIVE_BUILD && defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f")) {
    CHECK(name == "AVX-512");
  } else if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) {
    CHECK(name == "AVX2+FMA");
  } else if (__builtin_cpu_supports("avx")) {
    CHECK((name == "AVX" || name == "AVX2"));
  } else {
    CHECK(name != "AVX-512");
  }
#else
  SUCCEED("portable build (SBPTT_NATIVE=OFF) or no __builtin_cpu_supports: " << name);
#endif
}
