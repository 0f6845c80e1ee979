#pragma once
// Shared helpers of the libFuzzer targets (tests/fuzz/). Not part of the library.
//
// A fuzz target reports a finding by aborting: `expect` prints what went wrong and calls
// std::abort(), which libFuzzer records as a crash together with the input.
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <type_traits>

namespace sbptt_fuzz {

inline void expect(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz invariant violated: %s\n", what);
  std::abort();
}

/// True iff `a` and `b` hold the same bits (so -0 != +0, and NaN payloads count).
template <class Scalar>
[[nodiscard]] bool same_bits(const Scalar* a, const Scalar* b, std::size_t count) {
  return count == 0 || std::memcmp(a, b, count * sizeof(Scalar)) == 0;
}

/// The blanks the interchange formats allow around a number (docs/formats.md): space, tab, CR.
[[nodiscard]] inline bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r'; }

[[nodiscard]] inline std::string_view trim(std::string_view text) {
  while (!text.empty() && is_blank(text.front())) text.remove_prefix(1);
  while (!text.empty() && is_blank(text.back())) text.remove_suffix(1);
  return text;
}

/// An independent reading of one field with the C library (strtod / strtof in the "C"
/// locale, which libFuzzer never changes). Only consulted when sbptt accepted the field, so
/// the C library's wider grammar (hex floats, "inf", leading blanks) never matters; both are
/// correctly rounded, so an accepted field must give the same bits.
template <class Scalar>
[[nodiscard]] Scalar reference_value(std::string_view field) {
  const std::string text(trim(field));
  if constexpr (std::is_same_v<Scalar, float>)
    return std::strtof(text.c_str(), nullptr);
  else
    return static_cast<Scalar>(std::strtod(text.c_str(), nullptr));
}

/// A private scratch directory for the file round trips, removed at exit. Prefers /dev/shm
/// (no disk traffic) and falls back to the system temporary directory.
class ScratchDir {
public:
  ScratchDir() {
    std::error_code error;
    std::filesystem::path base = "/dev/shm";
    if (!std::filesystem::is_directory(base, error)) base = std::filesystem::temp_directory_path();
    std::string pattern = (base / "sbptt-fuzz-XXXXXX").string();
    if (::mkdtemp(pattern.data()) == nullptr) {
      std::fprintf(stderr, "cannot create a scratch directory under %s: %s\n",
                   base.c_str(), std::strerror(errno));
      std::abort();
    }
    path_ = pattern;
  }
  ~ScratchDir() {
    std::error_code error;
    std::filesystem::remove_all(path_, error);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  ScratchDir(ScratchDir&&) = delete;
  ScratchDir& operator=(ScratchDir&&) = delete;

  [[nodiscard]] std::filesystem::path file(const char* name) const { return path_ / name; }

private:
  std::filesystem::path path_;
};

/// Writes `bytes` to `path` as they are (the file a user could hand to a loader).
inline void write_bytes(const std::filesystem::path& path, std::string_view bytes) {
  std::FILE* out = std::fopen(path.c_str(), "wb");
  expect(out != nullptr, "cannot open the scratch file for writing");
  const std::size_t written = bytes.empty() ? 0 : std::fwrite(bytes.data(), 1, bytes.size(), out);
  expect(written == bytes.size(), "short write to the scratch file");
  expect(std::fclose(out) == 0, "cannot close the scratch file");
}

}  // namespace sbptt_fuzz
