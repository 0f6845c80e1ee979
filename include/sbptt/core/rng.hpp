#pragma once
/// \file Seeded random numbers with results that do not depend on the standard library.
///
/// `std::uniform_real_distribution` and `std::normal_distribution` are implementation-defined,
/// so a seed would give different data with libstdc++ and libc++. `Rng` draws from the fully
/// specified `std::mt19937_64` engine and converts the bits itself.
#include <cmath>
#include <cstdint>
#include <locale>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

namespace sbptt {

/// Deterministic generator; every random draw in sbptt takes one explicitly.
class Rng {
public:
  explicit Rng(std::uint64_t seed) : engine_(seed) {}

  /// Uniform on [0, 1) with 53 random bits.
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }

  /// Uniform on [low, high).
  double uniform(double low, double high) { return low + (high - low) * uniform(); }

  /// Standard normal by Box–Muller (one draw per call; the partner value is discarded so
  /// that the stream position does not depend on call history).
  double normal() {
    const double u1 = 1.0 - uniform();  // in (0, 1], so log is finite
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

  /// The raw 64-bit engine output (for seeding child generators).
  std::uint64_t bits() { return engine_(); }

  /// The engine's whole state as text (the standard's decimal words, in the classic locale
  /// whatever the global one), for checkpoints.
  [[nodiscard]] std::string state() const {
    std::ostringstream out;
    out.imbue(std::locale::classic());
    out << engine_;
    return out.str();
  }
  /// Restores a `state()`; returns false (leaving the generator unchanged) on malformed text,
  /// words after the state included.
  [[nodiscard]] bool restore(const std::string& state) {
    std::istringstream in(state);
    in.imbue(std::locale::classic());
    std::mt19937_64 engine;
    in >> engine;
    if (in.fail() || !(in >> std::ws).eof()) return false;
    engine_ = engine;
    return true;
  }

private:
  std::mt19937_64 engine_;
};

}  // namespace sbptt
