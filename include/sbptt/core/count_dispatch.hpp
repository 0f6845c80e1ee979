#pragma once
/// \file A count known only at run time, made a template argument: the register kernels are
/// instantiated for each width they may meet (1 to 7 samples left over, 1 to 7 panels).
#include <type_traits>
#include <utility>

#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Calls `f(std::integral_constant<int, c>{})` for the c in 1 … Max equal to `count`; does
/// nothing when `count` is outside 1 … Max.
template <int Max, class F>
void with_count(Index count, F&& f) {
  [&]<int... C>(std::integer_sequence<int, C...>) {
    ((count == C + 1 ? f(std::integral_constant<int, C + 1>{}) : void()), ...);
  }(std::make_integer_sequence<int, Max>{});
}

}  // namespace sbptt::detail
