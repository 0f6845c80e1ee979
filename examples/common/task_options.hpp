#pragma once
// The command line shared by the task programs (toy, cartpole, guidance, quantum). Defaults are
// the paper's settings (docs/programs.md); parse_task_options throws InvalidArgument naming the
// flag, the value and what was expected, before any work.
#include <charconv>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <sbptt/optim/clip.hpp>
#include <sbptt/train/method.hpp>
#include <sbptt/train/trainer.hpp>

#include "command_line.hpp"
#include "limits.hpp"

namespace sbptt::examples {

enum class Task { Toy, CartPole, Guidance, Quantum, Mujoco };

[[nodiscard]] constexpr const char* to_string(Task task) {
  switch (task) {
    case Task::Toy: return "toy";
    case Task::CartPole: return "cartpole";
    case Task::Guidance: return "guidance";
    case Task::Quantum: return "quantum";
    case Task::Mujoco: return "mujoco";
  }
  return "?";
}

/// The paper's time stepping of each task: steps and dt (T = steps · dt).
struct Horizon {
  long steps;
  double dt;
  [[nodiscard]] double horizon() const { return static_cast<double>(steps) * dt; }
};

[[nodiscard]] constexpr Horizon paper_horizon(Task task) {
  switch (task) {
    case Task::Toy: return {4, 1.0};  // a map: "dt" 1 only so that T counts the steps
    case Task::CartPole: return {100, 0.01};
    case Task::Guidance: return {60, 4.0 / 60.0};
    case Task::Quantum: return {128, 0.0625};
    case Task::Mujoco: return {100, 0.0};  // dt: the model's opt.timestep (`resolve_mujoco_time`)
  }
  return {1, 1.0};
}

/// The smallest quantum grid the reference CNN (two conv k3 s2) accepts: the first conv's
/// output, (nx − 3) / 2 + 1, must still hold one kernel of 3.
inline constexpr long min_quantum_nx = 7;

/// mujoco --target: each position in [−bound, bound].
inline constexpr double target_bound = 1e6;

/// Every setting of a task program, after parsing (the horizon resolved).
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
  bool chain = false;     ///< cart pole: the serial n-link chain (`--poles` links, 1..3)
  long drivers = 2;
  long evaders = 4;
  double rc = 0.1;
  long target = 2;  ///< quantum target, numbered as in the paper's plots (0 = ground state)
  long nx = 32;
  Horizon time{100, 0.01};  ///< steps and dt after --steps / --dt / --T
  // mujoco only: the scene and its task (examples/mujoco.cpp)
  std::string model;            ///< --model FILE.xml
  std::vector<double> positions;  ///< --target q1,...,qN (its length is checked once nq is known)
  double spread = 0.1;          ///< initial qpos = qpos0 + U[−spread, spread)
  bool check_derivatives = false;
  /// --steps, --dt, --T as given: mujoco resolves them once the model's timestep is known.
  std::optional<long> steps_flag;
  std::optional<double> dt_flag, horizon_flag;
  bool use_float = false;
  long threads = 1;
  // files
  std::string csv, save_params, init_params, init_states, dump_gradients;
  std::string checkpoint;
  long checkpoint_every = 1;  ///< epochs between checkpoints; 0 = only at the end
  long evaluate_every = 1;    ///< evaluate the train and test sets every k-th epoch and the last
  long patience = 0;          ///< stop after this many evaluations without a better test loss
  bool evaluate_beside = false;  ///< evaluate on a second thread while the next epoch trains
};

/// The cart pole's --model: "reference", "physical" (also --physical) or "chain".
inline const char* cart_pole_model(const TaskOptions& o) {
  return o.chain ? "chain" : o.physical ? "physical" : "reference";
}

/// " with --poles 4" and the like: the flags that set the size of the task's state, for the
/// messages about memory.
[[nodiscard]] inline std::string state_size_flags(const TaskOptions& o) {
  switch (o.task) {
    case Task::CartPole: return detail::concat(" with --poles ", o.poles);
    case Task::Guidance:
      return detail::concat(" with --drivers ", o.drivers, " and --evaders ", o.evaders);
    case Task::Quantum: return detail::concat(" with --nx ", o.nx);
    case Task::Mujoco: return detail::concat(" with --model '", o.model, "'");
    case Task::Toy: break;
  }
  return {};
}

namespace detail_task {

/// Steps of dt that make up T exactly; throws naming `flags` when T is not a whole number of
/// them or they exceed the count limit.
inline long whole_steps(double horizon, double dt, const std::string& flags) {
  const double steps = std::round(horizon / dt);
  detail::require(steps >= 1 && std::abs(steps * dt - horizon) < 1e-9 * horizon, flags,
                  ": T = ", shown(horizon), " is not a whole number of steps of dt = ", shown(dt),
                  " (", shown(horizon / dt), "); expected a dt that divides T, or --steps too");
  detail::require(steps <= static_cast<double>(limits::max_count), flags, ": T = ",
                  shown(horizon), " is ", shown(steps), " steps of dt = ", shown(dt),
                  "; expected at most ", limits::max_count, " steps");
  return static_cast<long>(steps);
}

/// `value`, the dt or T (`name`) that `flags` imply; throws unless it lies in the range of its
/// own flag (3 steps over T = 1e-12 would step by 3.3e-13).
inline double derived(const char* name, double value, double low, double high,
                      const std::string& flags) {
  detail::require(value >= low && value <= high, flags, ": ", name, " = ", shown(value),
                  " is out of range; expected ", name, " in ", range_text(low, high), ", as for --",
                  name);
  return value;
}

/// The time-stepping rules of docs/programs.md: --steps alone keeps dt (T changes); --dt alone
/// keeps T and --T alone keeps dt (steps adapt, T must be a whole number of steps); two of
/// them fix the third; all three is an error.
inline Horizon resolve(Horizon paper, std::optional<long> steps, std::optional<double> dt,
                       std::optional<double> horizon) {
  detail::require(!(steps && dt && horizon), "--steps, --dt and --T all given; expected at "
                                             "most two of them (T = steps · dt)");
  if (steps && horizon)
    return {*steps, derived("dt", *horizon / static_cast<double>(*steps), limits::min_dt,
                            limits::max_dt, detail::concat("--steps ", *steps, " with --T ",
                                                           shown(*horizon)))};
  if (steps) {
    const Horizon time{*steps, dt.value_or(paper.dt)};
    derived("T", time.horizon(), limits::min_horizon, limits::max_horizon,
            detail::concat("--steps ", *steps, dt ? " with --dt " : " at dt ", shown(time.dt)));
    return time;
  }
  if (dt && horizon) return {whole_steps(*horizon, *dt, "--dt with --T"), *dt};
  if (dt) return {whole_steps(paper.horizon(), *dt, "--dt " + shown(*dt)), *dt};
  if (horizon) return {whole_steps(*horizon, paper.dt, "--T " + shown(*horizon)), paper.dt};
  return paper;
}

/// With --float a rate must be a normal float: 1e300 would become inf, 1e-300 zero.
inline void require_float_range(const char* flag, double value) {
  constexpr double low = std::numeric_limits<float>::min();
  constexpr double high = std::numeric_limits<float>::max();
  detail::require(value >= low && value <= high, flag, " ", shown(value),
                  " does not fit --float; expected a number in ", range_text(low, high),
                  " with --float");
}

}  // namespace detail_task

/// "q1,q2,...": each number the shortest text that reads back as the same double.
[[nodiscard]] inline std::string comma_separated(const std::vector<double>& values) {
  std::string text;
  for (const double value : values) {
    char number[32];
    if (!text.empty()) text += ',';
    text.append(number, std::to_chars(number, number + sizeof number, value).ptr);
  }
  return text;
}

/// Parses argv for `task` into `o`. Returns false when --help printed the help (exit 0);
/// throws InvalidArgument on any unknown flag or bad value.
[[nodiscard]] inline bool parse_task_options(Task task, int argc, const char* const* argv,
                                             TaskOptions& o) {
  o = TaskOptions{};
  o.task = task;
  if (task == Task::Toy) {  // the paper's toy has one start and two parameters
    o.samples = 1;
    o.batch = 1;
    o.epochs = 200;
    o.lr = 0.01;
  }
  const Horizon paper = paper_horizon(task);
  std::optional<long> steps;
  std::optional<double> dt, horizon;
  const long many = limits::max_count;

  CommandLine cli(to_string(task), detail::concat(
      "sbptt task program '", to_string(task), "': trains a controller on ",
      task == Task::Mujoco ? "the MuJoCo scene of --model (docs/mujoco.md)" : "the paper's task",
      " with the chosen gradient (docs/programs.md). Exit codes: 0 success, 1 error, 2 bad "
      "flag, 3 a non-finite value stopped training",
      task == Task::Mujoco ? " or --check-derivatives found derivatives that disagree" : "",
      ", 128 + the signal (", 128 + SIGINT, ", ", 128 + SIGTERM, ", ", 128 + SIGHUP, ", ",
      128 + SIGXCPU, ") after SIGINT, SIGTERM, SIGHUP or SIGXCPU stopped training (after the "
      "epoch it came in, its outputs written; 0 when that was the last)."));
  cli.value("--method", "R|M|C|S|N",
            "gradient: regular, modified, combined, stopped, network-only (long names and "
            "full/physics/stop work too)", "C",
            [&](const std::string& text) { o.method = parse_method(text); });
  cli.value("--clip", "none|value|norm", "clipping of the vector fed to Adam (after combining)",
            "none", [&](const std::string& text) { o.clip = parse_clip_mode(text); });
  cli.number("--clip-threshold", o.clip_threshold, limits::min_positive, limits::max_positive,
             "threshold of --clip");
  cli.integer("--epochs", o.epochs, 0, many, "epochs to train (0 = only load and save)");
  cli.integer("--batch", o.batch, 1, many, "mini-batch size");
  cli.integer("--samples", o.samples, 1, many, "train samples; the test set has as many");
  cli.number("--lr", o.lr, limits::min_positive, limits::max_positive, "Adam learning rate");
  cli.integer("--seed", o.seed, 0, limits::max_seed,
              "seed of the data (and, plus 1, of the initial weights)");
  cli.flag("--shuffle", "reshuffle the train set every epoch (the reference never does); default off",
           [&] { o.shuffle = true; });
  cli.integer("--truncation", o.truncation, 0, many, "cut the adjoint every K steps (0 = never)");
  cli.value("--on-nonfinite", "stop|skip-batch",
            "what a NaN/Inf in a batch's update does: stop training, or skip that batch", "stop",
            [&](const std::string& text) {
              if (text == "stop") o.on_non_finite = NonFinitePolicy::Stop;
              else if (text == "skip-batch") o.on_non_finite = NonFinitePolicy::SkipBatch;
              else throw InvalidArgument(detail::concat("--on-nonfinite '", text,
                                                        "' is unknown; expected stop or skip-batch"));
            });
  cli.value("--steps", "N",
            detail::concat(task == Task::Toy ? "steps of the map, the horizon"
                                             : "time steps; alone it keeps dt and changes T",
                           "; an integer in [1, ", many, "]"),
            std::to_string(paper.steps),
            [&](const std::string& text) { steps = parse_integer("--steps", text, 1, many); });
  if (task == Task::Toy) {
    const char* reason = "the toy system x' = x + c is a map with no time step; expected --steps "
                         "alone to set the horizon";
    cli.refuse("--dt", reason);
    cli.refuse("--T", reason);
  } else {
    cli.value("--dt", "X",
              detail::concat("time step; alone it keeps T, which must then be a whole number of "
                             "steps; a number in ", range_text(limits::min_dt, limits::max_dt)),
              task == Task::Mujoco ? "the model's timestep" : shown(paper.dt),
              [&](const std::string& text) {
                dt = parse_number("--dt", text, limits::min_dt, limits::max_dt);
              });
    cli.value("--T", "X",
              detail::concat("horizon T = steps · dt; alone it keeps dt (a whole number of steps, "
                             "at most ", many, "); a number in ",
                             range_text(limits::min_horizon, limits::max_horizon)),
              task == Task::Mujoco ? "steps times dt" : shown(paper.horizon()),
              [&](const std::string& text) {
                horizon = parse_number("--T", text, limits::min_horizon, limits::max_horizon);
              });
  }
  cli.flag("--float", "compute in float (default: double)", [&] { o.use_float = true; });
  cli.flag("--double", "compute in double (the default)", [&] { o.use_float = false; });
  cli.integer("--threads", o.threads, 1, limits::max_threads,
              "threads over the samples of a batch (and a sweep's parameter products)");
  cli.path("--csv", o.csv, "training log, one row per epoch (docs/formats.md)");
  cli.path("--save-params", o.save_params, "write the trained parameters (docs/formats.md)");
  cli.path("--init-params", o.init_params, "start from these parameters (docs/formats.md)");
  cli.path("--init-states", o.init_states,
           "train on these initial states (docs/formats.md); the test set stays the generated one");
  cli.path("--dump-gradients", o.dump_gradients,
           "no training: evaluate the train states as one batch, print loss=<value>, write "
           "param,R,M,C,S,N; refuses the training flags");
  cli.path("--checkpoint", o.checkpoint,
           "resume from this checkpoint if it exists, and write it every --checkpoint-every "
           "epochs and at the end: rerunning a killed command resumes it (docs/training.md)");
  cli.integer("--checkpoint-every", o.checkpoint_every, 0, many,
              "epochs between checkpoints (0 = only at the end)");
  cli.integer("--evaluate-every", o.evaluate_every, 1, many,
              "evaluate the train and test sets every N-th epoch and the last");
  cli.integer("--patience", o.patience, 0, many,
              "stop after N evaluations without a better test loss (0 = never)");
  cli.flag("--evaluate-beside",
           "evaluate each epoch on a second thread while the next one trains: the same "
           "results, one more thread (docs/training.md)",
           [&] { o.evaluate_beside = true; });
  if (task == Task::CartPole) {
    cli.integer("--poles", o.poles, 1, 4, "number of poles");
  }
  if (task == Task::CartPole || task == Task::Guidance)
    cli.flag("--physical",
             "the physical variant instead of the reference's quirks (docs/simulators.md); "
             "default off",
             [&] { o.physical = true; });
  if (task == Task::CartPole)
    cli.value("--model", "reference|physical|chain",
              "cart-pole equations: the reference's, poles side by side coupled through the cart "
              "(= --physical), or --poles links hinged end to end (1 to 3; docs/simulators.md)",
              "reference", [&](const std::string& text) {
                if (text != "reference" && text != "physical" && text != "chain")
                  throw InvalidArgument(detail::concat("--model '", text, "' is unknown; expected "
                                                       "reference, physical or chain"));
                // Both set each time: the last --model given wins, as for every flag.
                o.physical = text == "physical";
                o.chain = text == "chain";
              });
  if (task == Task::Guidance) {
    cli.integer("--drivers", o.drivers, 1, 16, "drivers (2 and 4 evaders run fixed-size)");
    cli.integer("--evaders", o.evaders, 1, 64, "evaders");
    cli.number("--rc", o.rc, 0, 1e9, "weight of the control regulariser");
  }
  if (task == Task::Mujoco) {
    cli.path("--model", o.model,
             "the MJCF file of the scene (a URDF cannot name actuators); required", "none");
    cli.value("--target", "q1,...,qN",
              "final positions, one per qpos coordinate (nq of them; hinges in radians, compared "
              "as angles); required",
              "none", [&](const std::string& text) {
                o.positions.clear();
                for (std::size_t start = 0, item = 1;; ++item) {
                  const std::size_t comma = text.find(',', start);
                  const std::string part = text.substr(start, comma - start);
                  try {
                    o.positions.push_back(
                        parse_number("--target", part, -target_bound, target_bound));
                  } catch (const InvalidArgument&) {
                    throw InvalidArgument(detail::concat(
                        "--target '", text, "': item ", item, ", '", part, "', is not a number "
                        "in ", range_text(-target_bound, target_bound), "; expected "
                        "comma-separated numbers, one per position coordinate"));
                  }
                  if (comma == std::string::npos) break;
                  start = comma + 1;
                }
              });
    cli.number("--spread", o.spread, 0, 1e3,
               "initial states: qpos = qpos0 + U[-X, X) per coordinate, qvel = 0");
    cli.flag("--check-derivatives",
             "no training: print the worst error of check_jacobians at 5 initial states and "
             "whether it is below a smooth model's tolerance (else exit 3); refuses the flags "
             "of training, --target and the data flags",
             [&] { o.check_derivatives = true; });
  }
  if (task == Task::Quantum) {
    cli.integer("--target", o.target, 2, 4,
                "target state, counted as in the paper's plots (0 = ground state)");
    cli.integer("--nx", o.nx, min_quantum_nx, 4096,
                "interior grid points (at least 7: the CNN's two k3 s2 convolutions)");
  }
  if (!cli.parse(argc, argv)) return false;

  // The switches' callbacks run in the order they were declared, not given: --double won.
  detail::require(!(cli.given("--float") && cli.given("--double")), "--float and --double both "
                  "given; expected one of them (double is the default)");
  // --model's callback runs after --physical's, whichever came first, and would drop it.
  detail::require(task != Task::CartPole || !cli.given("--physical") || !cli.given("--model") ||
                      o.physical,
                  "--model ", cart_pole_model(o), " and --physical both given; expected one "
                  "cart-pole model (--physical is --model physical)");
  detail::require(!o.chain || o.poles <= 3, "--poles ", o.poles, " with --model chain; expected "
                                            "1 to 3 links");
  o.steps_flag = steps;
  o.dt_flag = dt;
  o.horizon_flag = horizon;
  // mujoco's dt is the model's, known only once it is loaded (resolve_mujoco_time).
  if (task != Task::Mujoco) o.time = detail_task::resolve(paper, steps, dt, horizon);
  if (o.use_float) {
    detail_task::require_float_range("--lr", o.lr);
    // Checked with --clip none too, as its double range is: a checkpoint records it.
    detail_task::require_float_range("--clip-threshold", o.clip_threshold);
  }
  // A flag a mode does not use is refused, not ignored: the user meant it to matter.
  const auto refuse = [&](const char* mode, const char* does, std::vector<const char*> flags) {
    for (const char* flag : {"--epochs", "--csv", "--save-params", "--batch", "--lr", "--shuffle",
                             "--method", "--clip", "--clip-threshold", "--on-nonfinite",
                             "--checkpoint", "--checkpoint-every", "--evaluate-every",
                             "--patience", "--evaluate-beside"})
      flags.push_back(flag);
    for (const char* flag : flags)
      detail::require(!cli.given(flag), mode, " ", does, ", so ", flag, " would have no effect; "
                      "expected ", mode, " without ", flag);
  };
  if (!o.dump_gradients.empty())
    refuse("--dump-gradients", "evaluates the parameters without training", {"--threads"});
  if (o.check_derivatives)
    refuse("--check-derivatives", "checks the model's Jacobians at 5 states without a controller",
           {"--dump-gradients", "--init-params", "--init-states", "--target", "--samples",
            "--truncation", "--threads"});
  return true;
}

/// The time stepping of a mujoco run: the flags resolved against the model's time step.
[[nodiscard]] inline Horizon resolve_mujoco_time(const TaskOptions& o, double model_dt) {
  // The model's step is held to --dt's range wherever it is used (as dt, or for T with --dt
  // alone), as the flag would be; two of the flags leave it unused.
  const int given = int{o.steps_flag.has_value()} + int{o.dt_flag.has_value()} +
                    int{o.horizon_flag.has_value()};
  detail::require(given >= 2 || (model_dt >= limits::min_dt && model_dt <= limits::max_dt),
                  "--model '", o.model, "': its opt.timestep ", shown(model_dt),
                  " is out of range; expected a number in ",
                  range_text(limits::min_dt, limits::max_dt),
                  " (or two of --steps, --dt and --T, which leave it unused)");
  return detail_task::resolve({paper_horizon(Task::Mujoco).steps, model_dt}, o.steps_flag,
                              o.dt_flag, o.horizon_flag);
}

}  // namespace sbptt::examples
