#pragma once
// What the four task programs (toy, cartpole, guidance, quantum) share: flag parsing with clear
// errors, the horizon rules, the data split, --dump-gradients, and the training loop with its
// log, progress line and non-finite handling. Each program only builds its simulator,
// objective, controller and initial states.
//
// Exit codes: 0 success, 1 error (unreadable file, out of memory, stdout or stderr not written
// in full, ...), 2 bad flags, 3 a non-finite value stopped training (--save-params still saves
// the parameters the trainer rolled back to: those of the last logged epoch, or the initial
// ones; mujoco: or --check-derivatives found derivatives that disagree), 128 + the signal:
// SIGINT, SIGTERM, SIGHUP or SIGXCPU stopped training after the epoch it came in (its log row,
// checkpoint and parameters written; a second one ends the program at once; one the program was
// started ignoring stays ignored: sbptt/train/stop_signals.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <iterator>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <sbptt/sbptt.hpp>

#include "memory_budget.hpp"
#include "standard_streams.hpp"
#include "task_options.hpp"

namespace sbptt::examples {

/// "100 steps of dt 0.01, T 1" for the header line (the toy is a map: steps only).
inline std::string describe(Task task, const Horizon& time) {
  if (task == Task::Toy) return detail::concat(time.steps, " steps (a map, no dt)");
  return detail::concat(time.steps, " steps of dt ", shown(time.dt), ", T ", shown(time.horizon()));
}

/// The train and test sets of --samples each.
template <class Scalar>
struct DataSplit {
  Matrix<Scalar> train, test;
};

/// 2 × --samples states from `generate(count)`, the first half the train set and the second
/// the test set, as the reference splits them; refused before anything is generated when a
/// run of `network` on them cannot fit in memory (memory_budget.hpp).
template <class Scalar, class Generate>
DataSplit<Scalar> generated_sets(const TaskOptions& o, Index state_dim,
                                 const Network<Scalar>& network, Generate&& generate) {
  require_memory_for_run<Scalar>(o, state_dim, network);
  const Matrix<Scalar> states = generate(Index{2} * o.samples);
  const Index n = states.cols() / 2;
  return {states.leftCols(n), states.rightCols(n)};
}

/// --dump-gradients: one batch (all of `states`), no update; prints loss=… and writes
/// `param,R,M,C,S,N`, one row per parameter. A non-finite loss, state, control or gradient is
/// reported on stderr and returns 3; nothing is written then.
template <class Sim, class Ctrl, class Loss>
int dump_gradients(const TaskOptions& o, const Sim& sim, Ctrl& controller,
                   const Objective<Loss>& objective, Index steps,
                   const Matrix<typename Sim::Scalar>& states) {
  using Scalar = typename Sim::Scalar;
  Engine engine(sim, controller, objective, steps);
  const Scalar loss = engine.forward(states);
  const auto refuse = [&](const std::string& what, const char* when, const NonFinite& where) {
    std::cerr << to_string(o.task) << ": --dump-gradients: non-finite " << what << " ("
              << detail::value_text(where.value) << ") " << when << describe_where(where)
              << detail::note_after("; ", detail::take_refusal_note(sim))
              << "; no gradients written\n";
    return 3;
  };
  if (const auto& where = engine.forward_non_finite())
    return refuse(std::string(to_string(where->quantity)), "in the forward pass", *where);
  Vector<Scalar> regular, modified, stopped, network, combined;
  engine.reverse(FlowMode::Full, regular, o.truncation);
  engine.reverse(FlowMode::PhysicsOnly, modified, o.truncation);
  engine.reverse(FlowMode::Stopped, stopped, o.truncation);
  engine.reverse(FlowMode::NetworkOnly, network, o.truncation);
  combine(modified, regular, combined);
  const std::pair<const char*, const Vector<Scalar>*> columns[] = {
      {"R", &regular}, {"M", &modified}, {"C", &combined}, {"S", &stopped}, {"N", &network}};
  for (const auto& [column, values] : columns)
    if (const auto where = detail::first_non_finite_component(*values, Quantity::Gradient))
      return refuse(detail::concat(column, " gradient"), "in the reverse sweep", *where);
  std::string text = "param,R,M,C,S,N\n";
  for (Index p = 0; p < regular.size(); ++p) {
    text += std::to_string(p);
    for (const auto& column : columns) {
      text += ',';
      detail::append_number(text, (*column.second)(p));
    }
    text += '\n';
  }
  write_file_atomically(o.dump_gradients, text);
  std::printf("loss=%.17g\n", static_cast<double>(loss));
  return 0;
}

/// FNV-1a of a file's bytes: the same content is the same file wherever it lies.
inline std::string file_fingerprint(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  detail::require<std::runtime_error>(in.is_open(), "cannot read '", path, "'");
  const std::string bytes{std::istreambuf_iterator<char>(in), {}};
  char text[64];
  std::snprintf(text, sizeof text, "fnv1a %016llx of %zu bytes",
                static_cast<unsigned long long>(detail::fnv1a(bytes.data(), bytes.size())),
                bytes.size());
  return text;
}

/// The settings besides the trainer's and the optimizer's that decide a task's result; a
/// checkpoint must have been made with the same. (--seed is recorded as the trainer's
/// shuffle_seed, which messages name --seed. --spread is listed, though the data's fingerprints
/// would catch it too, so that a changed value is reported as the flag.)
inline std::vector<RunSetting> task_identity(const TaskOptions& o) {
  std::vector<RunSetting> identity{{"task", to_string(o.task)},
                                   {"--samples", std::to_string(o.samples)},
                                   {"--steps", std::to_string(o.time.steps)},
                                   {"--dt", detail::concat(o.time.dt)}};
  if (o.task == Task::CartPole) {
    identity.push_back({"--model", cart_pole_model(o)});
    identity.push_back({"--poles", std::to_string(o.poles)});
  }
  if (o.task == Task::Guidance) {
    identity.push_back({"--physical", o.physical ? "yes" : "no"});
    identity.push_back({"--drivers", std::to_string(o.drivers)});
    identity.push_back({"--evaders", std::to_string(o.evaders)});
    identity.push_back({"--rc", detail::concat(o.rc)});
  }
  if (o.task == Task::Quantum) {
    identity.push_back({"--target", std::to_string(o.target)});
    identity.push_back({"--nx", std::to_string(o.nx)});
  }
  if (o.task == Task::Mujoco) {
    // The physics is the model file's content, which a path does not pin down.
    identity.push_back({"--model", file_fingerprint(o.model)});
    identity.push_back({"--target", comma_separated(o.positions)});
    identity.push_back({"--spread", comma_separated({o.spread})});  // the shortest exact text
  }
  return identity;
}

/// The file flags, checked by `task_main` before any work (drawing the sets of a large
/// --samples takes seconds): every output can be written, no file is named twice, and the
/// outputs' descriptors fit under `ulimit -n`.
inline void check_file_flags(const TaskOptions& o) {
  std::vector<std::string> outputs;
  for (const auto& [flag, path] :
       {std::pair{"--csv", &o.csv}, std::pair{"--checkpoint", &o.checkpoint},
        std::pair{"--save-params", &o.save_params},
        std::pair{"--dump-gradients", &o.dump_gradients}}) {
    if (path->empty()) continue;
    check_output_path(*path, flag);
    outputs.emplace_back(flag);
  }
  require_distinct_files({{"--model", o.task == Task::Mujoco ? o.model : std::string(), false},
                          {"--init-params", o.init_params, false},
                          {"--init-states", o.init_states, false},
                          {"--csv", o.csv, true},
                          {"--save-params", o.save_params, true},
                          {"--dump-gradients", o.dump_gradients, true},
                          {"--checkpoint", o.checkpoint, true},
                          {"--checkpoint's lock file", checkpoint_lock_path(o.checkpoint), false}});
  detail::require_descriptors_for_outputs(outputs, !o.csv.empty(), !o.checkpoint.empty());
}

/// `load()` of the input file `path` that `flag` names: its errors prefixed with the flag, and
/// memory that runs out while reading said to be the file's (`task_main`'s message for
/// std::bad_alloc names the run's sizes, which did not cause it).
template <class Load>
decltype(auto) load_input_file(const char* flag, const std::string& path, Load&& load) {
  try {
    return detail::prefixing_errors(flag, std::forward<Load>(load));
  } catch (const std::bad_alloc&) {
    throw IoError(detail::concat(flag, ": out of memory reading '", path,
                                 "'; expected a file whose numbers fit in memory"));
  }
}

/// Trains `controller` for o.epochs epochs (or dumps gradients) with `run_training`, printing
/// progress and every non-finite event to stderr.
template <class Sim, class Ctrl, class Loss>
int train(const TaskOptions& o, const Sim& sim, Ctrl& controller, const Objective<Loss>& objective,
          Index steps, DataSplit<typename Sim::Scalar> data) {
  using Scalar = typename Sim::Scalar;
  const char* name = to_string(o.task);
  if (!o.init_params.empty())
    load_input_file("--init-params", o.init_params,
                    [&] { load_parameters(o.init_params, controller); });
  if (!o.init_states.empty())
    data.train = load_input_file("--init-states", o.init_states, [&] {
      return load_states<Scalar>(o.init_states, sim.state_dim());
    });
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
               "%s, %ld parameters, %s, %s code%s\n",
               name, std::string(label(o.method)).c_str(), to_string(o.clip).c_str(), o.epochs,
               static_cast<long>(data.train.cols()), static_cast<long>(data.test.cols()), o.batch,
               describe(o.task, o.time).c_str(), static_cast<long>(controller.num_params()),
               o.use_float ? "float" : "double", instruction_set(),
               o.evaluate_beside ? ", each evaluation beside the next epoch's training" : "");
  RunSettings run;
  run.epochs = o.epochs;
  run.evaluate_every = o.evaluate_every;
  run.patience = o.patience;
  run.log_csv = o.csv;
  run.checkpoint = o.checkpoint;
  run.checkpoint_every = o.checkpoint_every;
  run.save_params = o.save_params;
  run.evaluate_beside = o.evaluate_beside;
  run.identity = task_identity(o);
  run.setting_names = {{"method", "--method"},
                       {"clip", "--clip"},
                       {"clip_threshold", "--clip-threshold"},
                       {"batch", "--batch"},
                       {"shuffle", "--shuffle"},
                       {"shuffle_seed", "--seed"},
                       {"truncation", "--truncation"},
                       {"on_non_finite", "--on-nonfinite"},
                       {"evaluate_every", "--evaluate-every"},
                       {"patience", "--patience"},
                       {"learning_rate", "--lr"},
                       {"epochs", "--epochs"},
                       {"log_csv", "--csv"},
                       {"checkpoint", "--checkpoint"},
                       {"save_params", "--save-params"},
                       {"scalar", "scalar (--float)"},
                       // Compared after --seed and --samples: what differs here is a file's
                       // content, or the way another build draws the sets and parameters.
                       {"initial parameters", "initial parameters (--init-params' content, "
                                              "else as this build draws them)"},
                       {"train set", "train set (--init-states' content, else as this build "
                                     "draws it)"},
                       {"test set", "test set (as this build draws it)"}};
  // Skipped batches are listed up to this many, then counted, so that a diverging run does
  // not flood stderr.
  constexpr long shown_skips = 5;
  long skips = 0;
  std::optional<StopSignals> stop_signals;
  RunCallbacks callbacks;
  callbacks.on_resume = [&](long epoch) {
    std::fprintf(stderr, "%s: resuming after epoch %ld from checkpoint '%s'\n", name, epoch,
                 o.checkpoint.c_str());
  };
  // Printed once run_training has checked everything: a refused checkpoint costs no
  // evaluation. The stop handlers come after it, so that Ctrl-C still ends the evaluation at
  // once, as it ends any work before the first epoch.
  callbacks.on_start = [&](long epoch) {
    const double loss = static_cast<double>(trainer.engine().evaluate(data.test));
    if (epoch == 0) {
      std::fprintf(stderr, "%s: initial test loss %.6g\n", name, loss);
    } else {
      std::fprintf(stderr, "%s: test loss of the resumed parameters %.6g\n", name, loss);
    }
    // Not as an event of epoch `epoch`: a resumed run's last epoch may not have been evaluated.
    // The simulator's refusals are taken here, so that the first event does not claim them.
    const std::string note = detail::note_after("; ", detail::take_refusal_note(sim));
    if (const auto& where = trainer.engine().forward_non_finite())
      std::fprintf(stderr, "%s: warning: the %s parameters give a non-finite %s (%s) in the test "
                           "set%s%s\n",
                   name, epoch == 0 ? "initial" : "resumed",
                   std::string(to_string(where->quantity)).c_str(),
                   detail::value_text(where->value).c_str(), describe_where(*where).c_str(),
                   note.c_str());
    stop_signals.emplace(name);
  };
  callbacks.on_non_finite = [&](const NonFiniteEvent& event, bool skipped) {
    if (skipped && ++skips > shown_skips) return;
    std::fprintf(stderr, "%s: %s%s\n", name, describe(event).c_str(),
                 skipped ? "; batch skipped" : "");
  };
  auto loss = [](const std::optional<double>& value) {
    char text[32] = "-";
    if (value) std::snprintf(text, sizeof text, "%.6g", *value);
    return std::string(text);
  };
  callbacks.on_epoch = [&](const EpochRecord& r) {
    if (r.epoch == 1 || r.epoch == o.epochs || r.epoch % 10 == 0)
      std::fprintf(stderr, "%s: epoch %ld  batch %.6g  train %s  test %s  %.3fs\n", name,
                   r.epoch, r.batch_loss, loss(r.train_loss).c_str(), loss(r.test_loss).c_str(),
                   r.seconds);
  };
  callbacks.should_stop = [&](const EpochRecord&) { return stop_signals->requested(); };
  const RunResult<Scalar> result = run_training(trainer, data.train, data.test, run, callbacks);
  const int signal = stop_signals ? stop_signals->signal() : 0;
  stop_signals.reset();
  if (skips > shown_skips)
    std::fprintf(stderr, "%s: %ld skipped batches in all (%ld not listed)\n", name, skips,
                 skips - shown_skips);
  const std::string saved =
      result.saved_params.empty() ? std::string()
                                  : detail::concat("; the parameters after epoch ", result.epochs,
                                                   " were saved to '", result.saved_params, "'");
  switch (result.end) {
    case RunEnd::NonFinite: {
      // A stop after a skipped batch means the whole epoch was skipped.
      const char* why = result.stop_event->phase == Phase::Update &&
                                o.on_non_finite == NonFinitePolicy::SkipBatch
                            ? " (no batch of it was finite)"
                            : "";
      // The kept epoch's own record: an epoch that was the last of an earlier run, resumed
      // from its checkpoint, was evaluated whatever --evaluate-every is now.
      const std::string last =
          result.last && result.last->train_loss
              ? std::string("the last whose evaluation was finite")
              : detail::concat("the last trained (not evaluated: --evaluate-every ",
                               o.evaluate_every, ")");
      const std::string kept = result.stop_event->epoch == 1
                                   ? std::string("it started from")
                                   : detail::concat("of epoch ", result.epochs, ", ", last);
      std::fprintf(stderr, "%s: training stopped in epoch %ld%s; keeping the parameters %s\n",
                   name, result.stop_event->epoch, why, kept.c_str());
      return 3;
    }
    case RunEnd::OutputFailed:
      std::fprintf(stderr, "%s: %s%s\n", name, result.output_error.c_str(), saved.c_str());
      return 1;
    case RunEnd::EarlyStop:
      std::fprintf(stderr, "%s: no better test loss in %ld evaluations: stopped after epoch %ld; "
                           "the best was %.9g in epoch %ld\n",
                   name, o.patience, result.epochs, result.best_loss, result.best_epoch);
      break;
    case RunEnd::Requested: {
      const std::string resume =
          o.checkpoint.empty()
              ? std::string("without --checkpoint a rerun starts from epoch 1")
              : detail::concat("checkpoint '", o.checkpoint,
                               "' holds it: run the same command again to resume");
      std::fprintf(stderr, "%s: stopped by %s after epoch %ld; %s%s\n", name,
                   signal_name(signal), result.epochs, resume.c_str(), saved.c_str());
      return 128 + signal;
    }
    case RunEnd::Finished:
      if (signal != 0)
        std::fprintf(stderr, "%s: %s came in the last epoch or after it: the run had finished\n",
                     name, signal_name(signal));
      break;
  }
  if (result.last && result.last->test_loss)
    std::printf("final test loss %.9g\n", *result.last->test_loss);
  return 0;
}

/// Parses the flags for `task` and calls `body.template operator()<Scalar>(options)` with
/// float or double; turns exceptions into messages and exit codes.
template <class Body>
int task_main(Task task, int argc, char** argv, Body&& body) {
  const char* name = to_string(task);
  TaskOptions options;
  const int code = [&] {
    try {
      if (!parse_task_options(task, argc, argv, options)) return 0;  // --help
    } catch (const InvalidArgument& e) {
      std::cerr << name << ": " << e.what() << "\n";
      return 2;
    }
    try {
      check_file_flags(options);
      return options.use_float ? body.template operator()<float>(options)
                               : body.template operator()<double>(options);
    } catch (const InvalidArgument& e) {
      std::cerr << name << ": " << e.what() << "\n";
      return 2;
    } catch (const ResourceError& e) {
      std::cerr << name << ": cannot start the threads of --threads " << options.threads
                << (options.evaluate_beside ? " and --evaluate-beside" : "") << ": " << e.what()
                << "\n";
      return 1;
    } catch (const std::bad_alloc&) {
      std::cerr << name << ": out of memory for --samples " << options.samples
                << " (and as many test samples)" << state_size_flags(options) << ", --batch "
                << options.batch << ", --steps " << options.time.steps << ", --threads "
                << options.threads
                << "; expected sizes whose data and trajectories fit in memory\n";
      return 1;
    } catch (const std::exception& e) {
      std::cerr << name << ": " << e.what() << "\n";
      return 1;
    }
  }();
  return with_streams_checked(name, code);
}

}  // namespace sbptt::examples
