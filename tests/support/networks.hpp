#pragma once
// The quantum-control CNN of the paper at any grid and width: (Nx positions × 2 channels) →
// conv `channels` k3 s2 tanh → conv `channels` k3 s2 tanh → flatten → dense 1. At Nx = 32 and
// 60 channels (the defaults) it is the paper's: 32 → 15 → 7 positions, 420 → 1.
#include "sbptt/nn/network.hpp"

namespace sbptt::testing {

template <class Scalar>
Network<Scalar> quantum_cnn(Index nx = 32, Index channels = 60) {
  const Conv1d first{nx, 2, channels, 3, 2, Activation::Tanh};
  const Conv1d second{first.output_length(), channels, channels, 3, 2, Activation::Tanh};
  return Network<Scalar>(
      {first, second, Dense{second.output_length() * channels, 1, Activation::Identity}});
}

}  // namespace sbptt::testing
