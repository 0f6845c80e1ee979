#pragma once
/// \file Text that identifies a value exactly, for the settings a checkpoint must share
/// (run.hpp): a number written so that it reads back bit for bit, and a hash of a matrix's
/// bytes with its shape (the train and test sets, the initial parameters).
#include <cstdint>
#include <cstdio>
#include <string>

#include "sbptt/core/number_text.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// FNV-1a: `hash` with the `size` bytes at `bytes` folded in.
[[nodiscard]] inline std::uint64_t fnv1a(const void* bytes, std::size_t size,
                                         std::uint64_t hash = 1469598103934665603ULL) {
  const auto* byte = static_cast<const unsigned char*>(bytes);
  for (std::size_t i = 0; i < size; ++i) hash = (hash ^ byte[i]) * 1099511628211ULL;
  return hash;
}

/// FNV-1a of the bytes of a matrix with its shape: equal data gives equal text.
template <class Derived>
[[nodiscard]] std::string fingerprint(const Eigen::DenseBase<Derived>& m) {
  std::uint64_t hash = fnv1a(nullptr, 0);
  for (Index j = 0; j < m.cols(); ++j) {
    for (Index i = 0; i < m.rows(); ++i) {
      const auto value = m(i, j);
      hash = fnv1a(&value, sizeof value, hash);
    }
  }
  char text[64];
  std::snprintf(text, sizeof text, "%ldx%ld fnv1a %016llx", static_cast<long>(m.rows()),
                static_cast<long>(m.cols()), static_cast<unsigned long long>(hash));
  return text;
}

template <class Number>
[[nodiscard]] std::string exact(Number value) {
  std::string text;
  append_number(text, value);
  return text;
}

}  // namespace sbptt::detail
