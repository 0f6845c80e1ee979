#pragma once
/// \file Rounding a register of doubles to integers without a conversion: for |x| < 2^51,
///
///     (x + 1.5·2^52) − 1.5·2^52 = round(x)   (to nearest, ties to even),
///
/// because the sum's exponent is 52, so its last mantissa bit is worth 1, and its low mantissa
/// bits hold round(x) (two's complement, biased by 2^51). The double kernels use it where the
/// integer is wanted in both forms: the tanh (nn/tanh_double.hpp) shifts the biased bits into
/// 2^k, the sine and cosine (core/sine_cosine.hpp) reduce by n π/2. It relies on IEEE rounding,
/// so neither is for -ffast-math.

namespace sbptt::detail {

/// 1.5·2^52: adding it rounds a double of magnitude below 2^51 (see the file comment).
inline constexpr double round_to_integer_shift = 6755399441055744.0;

}  // namespace sbptt::detail
