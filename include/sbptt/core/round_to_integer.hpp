#pragma once
/// \file Rounding a register of doubles to integers without a conversion: for |x| < 2^51,
///
///     (x + 1.5·2^52) − 1.5·2^52 = round(x)   (to nearest, ties to even),
///
/// because the sum's exponent is 52, so its last mantissa bit is worth 1: its mantissa field
/// holds 2^51 + round(x). The tanh (nn/tanh_double.hpp) uses both forms, k as a double and the
/// sum's low bits shifted into the exponent field of 2^k; the sine and cosine
/// (core/sine_cosine.hpp) use n of the reduction by n π/2. It relies on IEEE rounding, so
/// neither kernel is for -ffast-math.

namespace sbptt::detail {

/// 1.5·2^52: adding it rounds a double of magnitude below 2^51 (see the file comment).
inline constexpr double round_to_integer_shift = 6755399441055744.0;

}  // namespace sbptt::detail
