#pragma once
/// \file The one command-line interface shared by the task programs (toy, cartpole, guidance,
/// quantum). Defaults are the paper's settings; `parse_task_options` throws
/// `InvalidArgument` naming the flag and what was expected.
#include <cstdint>
#include <optional>
#include <string>

#include "sbptt/optim/clip.hpp"
#include "sbptt/train/arguments.hpp"
#include "sbptt/train/method.hpp"
#include "sbptt/train/trainer.hpp"

namespace sbptt {

enum class Task { Toy, CartPole, Guidance, Quantum };

[[nodiscard]] constexpr const char* to_string(Task task) {
  switch (task) {
    case Task::Toy: return "toy";
    case Task::CartPole: return "cartpole";
    case Task::Guidance: return "guidance";
    case Task::Quantum: return "quantum";
  }
  return "?";
}

/// Every setting of a task program. Unset optionals take the task's paper default.
struct TaskOptions {
  Task task = Task::CartPole;
  Method method = Method::Combined;
  ClipMode clip = ClipMode::None;
  double clip_threshold = 1.0;
  long epochs = 1000;
  long batch = 8;
  long samples = 256;  ///< train samples; the test set has as many
  double lr = 1e-3;
  std::uint64_t seed = 42;
  bool shuffle = false;
  long truncation = 0;
  NonFinitePolicy on_non_finite = NonFinitePolicy::Stop;
  // task sizes
  long poles = 1;
  bool physical = false;  ///< cart pole and guidance: the physical variants, not the reference quirks
  long drivers = 2;
  long evaders = 4;
  double rc = 0.1;
  long target = 2;  ///< quantum target, numbered as in the paper's plots (0 = ground state)
  long nx = 32;
  std::optional<long> steps;
  std::optional<double> dt;
  std::optional<double> horizon;  ///< T; with steps it fixes dt = T / steps
  bool use_float = false;
  long threads = 1;
  // files
  std::string csv, save_params, init_params, init_states, dump_gradients;
};

/// Upper bound of the count flags (--epochs, --batch, --samples, --steps, --truncation): far
/// above the paper's runs (1000 epochs, 256 samples, 128 steps), and low enough that a typo of
/// a few zeros is a flag error rather than an allocation failure an hour in.
inline constexpr long max_count = 1'000'000;

/// The accepted flags, for help and error messages.
[[nodiscard]] inline std::string task_flags(Task task) {
  std::string flags =
      "--method R|M|C|S|N, --clip none|value|norm, --clip-threshold X, --epochs N, --batch N, "
      "--samples N, --lr X, --seed N, --shuffle, --truncation K, --on-nonfinite stop|skip-batch, "
      "--steps N, --float, --double, --threads N, --csv FILE, --save-params FILE, "
      "--init-params FILE, --init-states FILE, --dump-gradients FILE";
  if (task != Task::Toy) flags += ", --dt X, --T X";
  if (task == Task::CartPole) flags += ", --poles 1..4, --physical";
  if (task == Task::Guidance) flags += ", --drivers D, --evaders E, --rc X, --physical";
  if (task == Task::Quantum) flags += ", --target 2..4, --nx N";
  return flags;
}

/// Parses argv for `task`; throws InvalidArgument on any unknown flag or bad value.
[[nodiscard]] inline TaskOptions parse_task_options(Task task, int argc, const char* const* argv) {
  TaskOptions o;
  o.task = task;
  if (task == Task::Toy) {  // the paper's toy has one start and two parameters
    o.samples = 1;
    o.batch = 1;
    o.epochs = 200;
    o.lr = 0.01;
  }
  ArgumentCursor args(argc, argv);
  while (args.next()) {
    const std::string& f = args.flag();
    if (f == "--method") o.method = parse_method(args.value());
    else if (f == "--clip") o.clip = parse_clip_mode(args.value());
    else if (f == "--clip-threshold") o.clip_threshold = parse_number(f, args.value(), 1e-300, 1e300);
    else if (f == "--epochs") o.epochs = parse_integer(f, args.value(), 0, max_count);
    else if (f == "--batch") o.batch = parse_integer(f, args.value(), 1, max_count);
    else if (f == "--samples") o.samples = parse_integer(f, args.value(), 1, max_count);
    else if (f == "--lr") o.lr = parse_number(f, args.value(), 1e-300, 1e300);
    else if (f == "--seed") o.seed = static_cast<std::uint64_t>(parse_integer(f, args.value(), 0, std::numeric_limits<long>::max()));
    else if (f == "--shuffle") args.no_value(), o.shuffle = true;
    else if (f == "--truncation") o.truncation = parse_integer(f, args.value(), 0, max_count);
    else if (f == "--on-nonfinite") {
      const std::string v = args.value();
      if (v == "stop") o.on_non_finite = NonFinitePolicy::Stop;
      else if (v == "skip-batch") o.on_non_finite = NonFinitePolicy::SkipBatch;
      else throw InvalidArgument(detail::concat("--on-nonfinite '", v, "'; expected stop or skip-batch"));
    }
    else if (f == "--steps") o.steps = parse_integer(f, args.value(), 1, max_count);
    else if ((f == "--dt" || f == "--T") && task == Task::Toy)
      throw InvalidArgument(detail::concat(f, ": the toy system x' = x + c is a map with no time "
                                              "step; expected --steps alone to set the horizon"));
    else if (f == "--dt") o.dt = parse_number(f, args.value(), 1e-12, 1e6);
    else if (f == "--T") o.horizon = parse_number(f, args.value(), 1e-12, 1e9);
    else if (f == "--float") args.no_value(), o.use_float = true;
    else if (f == "--double") args.no_value(), o.use_float = false;
    else if (f == "--threads") o.threads = parse_integer(f, args.value(), 1, 256);
    else if (f == "--csv") o.csv = args.value();
    else if (f == "--save-params") o.save_params = args.value();
    else if (f == "--init-params") o.init_params = args.value();
    else if (f == "--init-states") o.init_states = args.value();
    else if (f == "--dump-gradients") o.dump_gradients = args.value();
    else if (f == "--poles" && task == Task::CartPole) o.poles = parse_integer(f, args.value(), 1, 4);
    else if (f == "--physical" && (task == Task::CartPole || task == Task::Guidance))
      args.no_value(), o.physical = true;
    else if (f == "--drivers" && task == Task::Guidance) o.drivers = parse_integer(f, args.value(), 1, 16);
    else if (f == "--evaders" && task == Task::Guidance) o.evaders = parse_integer(f, args.value(), 1, 64);
    else if (f == "--rc" && task == Task::Guidance) o.rc = parse_number(f, args.value(), 0, 1e9);
    else if (f == "--target" && task == Task::Quantum) o.target = parse_integer(f, args.value(), 2, 4);
    else if (f == "--nx" && task == Task::Quantum) o.nx = parse_integer(f, args.value(), 4, 4096);
    else args.unknown(task_flags(task));
  }
  detail::require(!(o.steps && o.dt && o.horizon), "--steps, --dt and --T all given; expected at "
                                                   "most two of them (T = steps · dt)");
  return o;
}

}  // namespace sbptt
