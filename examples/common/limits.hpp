#pragma once
// The numeric limits of every program's command line, one set shared by the task programs
// (toy, cartpole, guidance, quantum) and the reproduction runner, so that a value one of them
// accepts is never refused by the other half-way through a sweep.
#include <limits>

namespace sbptt::examples::limits {

/// Upper bound of the count flags (--epochs, --batch, --samples, --steps, --truncation, and
/// the steps --T may imply): far above the paper's runs (1000 epochs, 256 samples, 128
/// steps), and low enough that a typo of a few zeros is a flag error rather than an allocation
/// failure an hour in.
inline constexpr long max_count = 1'000'000;
/// --dt and --T, and the dt or T the other time flags imply: beyond them the paper's tasks
/// no longer give a finite loss (10⁶ steps of dt 1e6 gave a test loss of nan).
inline constexpr double min_dt = 1e-12;
inline constexpr double max_dt = 1e6;
inline constexpr double min_horizon = 1e-12;
inline constexpr double max_horizon = 1e9;
/// --threads (a task program's threads over the samples of a batch, the runner's per run) and
/// the runner's --jobs.
inline constexpr long max_threads = 256;
/// --seed: any non-negative long.
inline constexpr long max_seed = std::numeric_limits<long>::max();
/// --lr and --clip-threshold lie in [min_positive, max_positive] (and must fit the scalar
/// type: with --float, in float's normal range).
inline constexpr double min_positive = 1e-300;
inline constexpr double max_positive = 1e300;
/// The runner's --seeds (seeds 42, 43, ... per configuration).
inline constexpr long max_seeds = 1000;

}  // namespace sbptt::examples::limits
