#pragma once
/// \file The update methods of the paper: the four flow modes plus the combined update.
#include <algorithm>
#include <cctype>
#include <optional>
#include <string>
#include <string_view>

#include "sbptt/bptt/flow_mode.hpp"
#include "sbptt/core/error.hpp"

namespace sbptt {

/// What the optimizer is fed (paper labels R, M, C, S; N for completeness).
enum class Method { Regular, Modified, Combined, Stopped, NetworkOnly };

/// The one-letter label used in logs and plots.
[[nodiscard]] constexpr std::string_view label(Method method) {
  switch (method) {
    case Method::Regular: return "R";
    case Method::Modified: return "M";
    case Method::Combined: return "C";
    case Method::Stopped: return "S";
    case Method::NetworkOnly: return "N";
  }
  return "?";
}

/// The single flow mode of a method; none for Combined, which needs two sweeps.
[[nodiscard]] constexpr std::optional<FlowMode> flow_mode(Method method) {
  switch (method) {
    case Method::Regular: return FlowMode::Full;
    case Method::Modified: return FlowMode::PhysicsOnly;
    case Method::Stopped: return FlowMode::Stopped;
    case Method::NetworkOnly: return FlowMode::NetworkOnly;
    case Method::Combined: return std::nullopt;
  }
  return std::nullopt;
}

/// Parses R|M|C|S|N or a long name (regular, modified, combined, stopped, network; also the
/// reference code's full, physics, stop), case-insensitively.
[[nodiscard]] inline Method parse_method(std::string_view text) {
  std::string lower(text);
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (lower == "r" || lower == "regular" || lower == "full" || lower == "f") return Method::Regular;
  if (lower == "m" || lower == "modified" || lower == "physics" || lower == "p")
    return Method::Modified;
  if (lower == "c" || lower == "combined") return Method::Combined;
  if (lower == "s" || lower == "stopped" || lower == "stop") return Method::Stopped;
  if (lower == "n" || lower == "network" || lower == "network-only") return Method::NetworkOnly;
  throw InvalidArgument(detail::concat("method '", text,
                                       "' is unknown; expected one of R, M, C, S, N (or regular, "
                                       "modified, combined, stopped, network)"));
}

}  // namespace sbptt
