#pragma once
// What the four task programs (toy, cartpole, guidance, quantum) share: flag parsing with clear
// errors, the horizon rules, the data split, --dump-gradients, and the training loop with its
// log, progress line and non-finite handling. Each program only builds its simulator,
// objective, controller and initial states.
//
// Exit codes: 0 success, 1 error (unreadable file, out of memory, ...), 2 bad flags, 3 a
// non-finite value stopped training (--save-params still saves the parameters the trainer rolled
// back to: those of the last logged epoch, or the initial ones).
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <unistd.h>
#include <iostream>
#include <new>
#include <string>

#include <sbptt/sbptt.hpp>

namespace sbptt::examples {

/// Time stepping of a task after --steps / --dt / --T. Given only --steps, dt is kept (the
/// horizon changes); given only --dt or only --T, the other one of steps and dt is adapted.
struct Horizon {
  Index steps;
  double dt;
  [[nodiscard]] double horizon() const { return static_cast<double>(steps) * dt; }
};

inline Horizon resolve_horizon(const TaskOptions& o, Index default_steps, double default_dt) {
  Horizon h{default_steps, default_dt};
  if (o.steps) h.steps = *o.steps;
  if (o.dt) h.dt = *o.dt;
  if (o.horizon && o.steps) h.dt = *o.horizon / static_cast<double>(*o.steps);
  if (o.horizon && !o.steps) {
    const double steps = std::round(*o.horizon / h.dt);
    detail::require(steps >= 1 && std::abs(steps * h.dt - *o.horizon) < 1e-9 * *o.horizon,
                    "--T ", *o.horizon, " is not a whole number of steps of dt = ", h.dt,
                    "; give --steps too, or a --dt that divides T");
    detail::require(steps <= static_cast<double>(max_count), "--T ", *o.horizon, " is ", steps,
                    " steps of dt = ", h.dt, "; expected at most ", max_count, " steps");
    h.steps = static_cast<Index>(steps);
  }
  return h;
}

/// Fails before any work when an output file could not be written: its directory must exist
/// and be writable, and the path itself must be a regular file or new (an hours-long run must
/// not die at its first save, nor lose its work when the final rename fails).
inline void require_writable(const std::string& path, const char* flag) {
  if (path.empty()) return;
  std::error_code error;
  const auto status = std::filesystem::status(path, error);
  detail::require<IoError>(!std::filesystem::exists(status) ||
                               std::filesystem::is_regular_file(status),
                           flag, " '", path, "' exists and is not a regular file (",
                           std::filesystem::is_directory(status) ? "a directory" : "a special file",
                           "); expected a file path to write");
  const std::filesystem::path parent = std::filesystem::absolute(path).parent_path();
  detail::require<IoError>(std::filesystem::exists(parent, error), flag, " '", path,
                           "': directory '", parent.string(), "' does not exist");
  detail::require<IoError>(std::filesystem::is_directory(parent, error), flag, " '", path,
                           "': '", parent.string(), "' is not a directory");
  detail::require<IoError>(::access(parent.c_str(), W_OK) == 0, flag, " '", path,
                           "': directory '", parent.string(), "' is not writable");
}

/// Splits 2N generated samples into the first N (train) and last N (test), as the reference.
template <class Scalar>
struct DataSplit {
  Matrix<Scalar> train, test;
};
template <class Scalar>
DataSplit<Scalar> split_half(const Matrix<Scalar>& states) {
  const Index n = states.cols() / 2;
  return {states.leftCols(n), states.rightCols(n)};
}

/// --dump-gradients: one batch (all of `states`), no update; prints loss=… and writes
/// `param,R,M,C,S,N`, one row per parameter.
template <class Sim, class Ctrl, class Loss>
int dump_gradients(const TaskOptions& o, const Sim& sim, Ctrl& controller,
                   const Objective<Loss>& objective, Index steps,
                   const Matrix<typename Sim::Scalar>& states) {
  using Scalar = typename Sim::Scalar;
  Engine engine(sim, controller, objective, steps);
  const Scalar loss = engine.forward(states);
  Vector<Scalar> regular, modified, stopped, network, combined;
  engine.reverse(FlowMode::Full, regular, o.truncation);
  engine.reverse(FlowMode::PhysicsOnly, modified, o.truncation);
  engine.reverse(FlowMode::Stopped, stopped, o.truncation);
  engine.reverse(FlowMode::NetworkOnly, network, o.truncation);
  combine(modified, regular, combined);
  std::string text = "param,R,M,C,S,N\n";
  for (Index p = 0; p < regular.size(); ++p) {
    text += std::to_string(p);
    for (const auto* column : {&regular, &modified, &combined, &stopped, &network}) {
      text += ',';
      detail::append_number(text, (*column)(p));
    }
    text += '\n';
  }
  write_file_atomically(o.dump_gradients, text);
  std::printf("loss=%.17g\n", static_cast<double>(loss));
  return 0;
}

/// "non-finite state (inf) in epoch 2, batch 1, step 9, sample 0", for the user's stderr.
inline std::string describe(const NonFiniteEvent& event) {
  const NonFinite& where = event.where;
  std::string text =
      detail::concat("non-finite ", to_string(where.quantity), " (", where.value, ") in ");
  text += event.phase == Phase::Update
              ? detail::concat("epoch ", event.epoch, ", batch ", event.batch)
              : detail::concat("the ", to_string(event.phase), " of epoch ", event.epoch);
  text += where.quantity == Quantity::Gradient
              ? detail::concat(", parameter ", where.sample)
              : detail::concat(", step ", where.step, ", sample ", where.sample);
  return text;
}

/// Trains `controller` for o.epochs epochs (or dumps gradients), writing the log and params.
template <class Sim, class Ctrl, class Loss>
int train(const TaskOptions& o, const Sim& sim, Ctrl& controller, const Objective<Loss>& objective,
          Index steps, DataSplit<typename Sim::Scalar> data) {
  using Scalar = typename Sim::Scalar;
  const char* name = to_string(o.task);
  require_writable(o.csv, "--csv");
  require_writable(o.save_params, "--save-params");
  require_writable(o.dump_gradients, "--dump-gradients");
  if (!o.init_params.empty()) load_parameters(o.init_params, controller);
  if (!o.init_states.empty()) data.train = load_states<Scalar>(o.init_states, sim.state_dim());
  if (!o.dump_gradients.empty())
    return dump_gradients(o, sim, controller, objective, steps, data.train);

  TrainerOptions options;
  options.method = o.method;
  options.clip = o.clip;
  options.clip_threshold = o.clip_threshold;
  options.batch = o.batch;
  options.shuffle = o.shuffle;
  options.shuffle_seed = o.seed;
  options.truncation = o.truncation;
  options.on_non_finite = o.on_non_finite;
  options.threads = o.threads;
  AdamOptions<Scalar> adam;
  adam.learning_rate = static_cast<Scalar>(o.lr);
  Trainer trainer(sim, controller, objective, steps, Adam<Scalar>(adam), options);

  std::fprintf(stderr,
               "%s: method %s, clip %s, %ld epochs, %ld train / %ld test samples, batch %ld, "
               "%ld steps, %ld parameters, %s\n",
               name, std::string(label(o.method)).c_str(), to_string(o.clip).c_str(), o.epochs,
               static_cast<long>(data.train.cols()), static_cast<long>(data.test.cols()), o.batch,
               static_cast<long>(steps), static_cast<long>(controller.num_params()),
               o.use_float ? "float" : "double");
  TrainingLog log;
  const double initial = static_cast<double>(trainer.engine().evaluate(data.test));
  std::fprintf(stderr, "%s: initial test loss %.6g\n", name, initial);
  if (const auto& where = trainer.engine().forward_non_finite())
    std::fprintf(stderr, "%s: warning: the initial parameters give a %s\n", name,
                 describe(NonFiniteEvent{0, -1, *where, Phase::TestEvaluation}).c_str());
  // Skipped batches are listed up to this many, then counted, so that a diverging run does
  // not flood stderr.
  constexpr long shown_skips = 5;
  long skips = 0;
  auto skipped = [&](const NonFiniteEvent& event) {
    return event.phase == Phase::Update && o.on_non_finite == NonFinitePolicy::SkipBatch;
  };
  int status = 0;
  for (long epoch = 1; epoch <= o.epochs; ++epoch) {
    const EpochRecord record = trainer.train_epoch(data.train, data.test);
    for (const NonFiniteEvent& event : trainer.non_finite_events()) {
      if (skipped(event) && ++skips > shown_skips) continue;
      std::fprintf(stderr, "%s: %s%s\n", name, describe(event).c_str(),
                   skipped(event) ? "; batch skipped" : "");
    }
    if (trainer.stopped()) {
      // A stop after a skipped batch means the whole epoch was skipped.
      const char* why =
          skipped(trainer.non_finite_events().back()) ? " (no batch of it was finite)" : "";
      const std::string kept =
          epoch == 1 ? std::string("it started from")
                     : detail::concat("of epoch ", epoch - 1,
                                      ", the last whose evaluation was finite");
      std::fprintf(stderr, "%s: training stopped in epoch %ld%s; keeping the parameters %s\n",
                   name, epoch, why, kept.c_str());
      status = 3;
      break;
    }
    log.add(record);
    if (!o.csv.empty()) log.save(o.csv);
    if (epoch == 1 || epoch == o.epochs || epoch % 10 == 0)
      std::fprintf(stderr, "%s: epoch %ld  batch %.6g  train %.6g  test %.6g  %.3fs\n", name,
                   epoch, record.batch_loss, record.train_loss, record.test_loss, record.seconds);
  }
  if (skips > shown_skips)
    std::fprintf(stderr, "%s: %ld skipped batches in all (%ld not listed)\n", name, skips,
                 skips - shown_skips);
  if (!o.save_params.empty()) save_parameters(o.save_params, controller);
  if (status == 0 && !log.rows().empty())
    std::printf("final test loss %.9g\n", log.rows().back().test_loss);
  return status;
}

/// Parses the flags for `task` and calls `body.template operator()<Scalar>(options)` with
/// float or double; turns exceptions into messages and exit codes.
template <class Body>
int task_main(Task task, int argc, char** argv, Body&& body) {
  const char* name = to_string(task);
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--help") {
      std::printf("usage: %s [flags]\nflags: %s\n", name, task_flags(task).c_str());
      return 0;
    }
  }
  TaskOptions options;
  try {
    options = parse_task_options(task, argc, argv);
  } catch (const InvalidArgument& e) {
    std::cerr << name << ": " << e.what() << "\n";
    return 2;
  }
  try {
    return options.use_float ? body.template operator()<float>(options)
                             : body.template operator()<double>(options);
  } catch (const InvalidArgument& e) {
    std::cerr << name << ": " << e.what() << "\n";
    return 2;
  } catch (const std::bad_alloc&) {
    const std::string nx = task == Task::Quantum ? ", --nx " + std::to_string(options.nx) : "";
    std::cerr << name << ": out of memory for --samples " << options.samples
              << " (and as many test samples), --batch " << options.batch << ", --steps "
              << (options.steps ? std::to_string(*options.steps) : "default") << nx
              << ", --threads " << options.threads
              << "; expected sizes whose data and trajectories fit in memory\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << name << ": " << e.what() << "\n";
    return 1;
  }
}

}  // namespace sbptt::examples
