#pragma once
/// \file What bench measures for one row and how it builds each task's row, in a child process.

#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <exception>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <sbptt/sbptt.hpp>

#include "counting_network.hpp"
#include "host_probes.hpp"
#include "scene_routes.hpp"

namespace bench {

using sbptt::Index;
using sbptt::Matrix;
using sbptt::Method;
using sbptt::Network;

struct Settings {
  std::string csv;
  int repeats = 2;
  Index threads = 2;
  /// How the threaded trainer runs a batch whose sweep meets the other thread at every step.
  sbptt::SweepThreading sweep_threading = sbptt::SweepThreading::Timed;
  std::vector<std::string> tasks = {"cartpole1",     "cartpole4",    "cartpole4-auto",
                                    "cartpole4-ode", "guidance",     "guidance-auto",
                                    "guidance-ode",  "quantum",      "quantum-nx"};
  std::vector<std::string> scalars = {"float", "double"};
  std::string methods = "RMCS";
};

/// What one row measures (plain data: it crosses a pipe from the child process).
struct RowResult {
  long long nx = 0, steps = 0, params = 0;  ///< state size (Nx for quantum), horizon, θ size
  double ms_epoch = 0, gflop = 0, ms_threads = 0, sim_ns = 0;
  double peak_gflops = 0;  ///< `measure_peak` of the row's scalar, in turn with its epochs
  double ms_regular = 0;   ///< a C row's R epochs, in turn with its own (0: not a C row)
  double round_trip_ns = 0;  ///< `cross_core_round_trip_ns` after the N-thread epochs (0: none)
  double other_core_read_ratio = 0;  ///< `other_core_read_ratio()` after them (0: none)
  double copies_ratio = 0;  ///< `concurrent_copies_ratio` of the 1-thread epoch (0: none)
  /// The epoch's evaluation of the two sets (`Engine::evaluate`), at 1 and at N threads, in
  /// turn with the epochs (0: one thread): the rest of an epoch is its training batches.
  double ms_evaluation = 0, ms_evaluation_threads = 0;
  /// An epoch whose evaluation runs beside the next epoch's training (`evaluate_beside` of
  /// `run_training`): the training on one thread, the evaluation of the epoch before on a
  /// second, timed together; and the same trainer's 1-thread epoch (uncounted network, unlike
  /// `ms_epoch`); both in turn with the epochs (0: one thread).
  double ms_beside = 0, ms_beside_alone = 0;
  /// Of the N-thread trainer's sweeps whose threads meet at every step (`SweepThreading`), how
  /// many ran on the threads and how many on one thread, over its timed epochs.
  long long sweeps_threaded = 0, sweeps_alone = 0;
  double trajectory_bytes = 0, rss_kib = 0;
  int ok = 0;
  char error[512] = {};  // room for a refusal of threads, with its flag and what it asks for

  [[nodiscard]] double gflops() const { return gflop / (ms_epoch / 1e3); }  ///< 1 thread
  [[nodiscard]] double fraction_of_peak() const { return gflops() / peak_gflops; }
};

struct Row {
  std::string task, scalar, method;
  RowResult result;
};

/// ns per sample of `step` + full `vjp` over the stored trajectory of the engine.
template <class Sim, class Engine>
double simulator_ns(const Sim& sim, const Engine& engine) {
  const auto& tr = engine.trajectory();
  typename Sim::State x(sim.state_dim()), next(sim.state_dim()), lx(sim.state_dim());
  typename Sim::Control u(sim.control_dim()), lu(sim.control_dim());
  Matrix<typename Sim::Scalar> batch_next, batch_x, batch_u;
  double best = 1e300;
  typename Sim::Scalar sum = 0;  // consumed below, so that no call can be optimised away
  for (int repeat = 0; repeat < 3; ++repeat) {
    const double start = now_ms();
    for (Index n = 0; n < tr.steps(); ++n) {
      const auto i = static_cast<std::size_t>(n);
      if constexpr (sbptt::BatchSimulator<Sim>) {  // what the engine calls for such a simulator
        sim.step_batch(tr.states[i], tr.controls[i], batch_next);
        sim.vjp_batch(tr.states[i], tr.controls[i], batch_next, &batch_x, &batch_u);
        sum += batch_next(0, 0) + batch_x(0, 0) + batch_u(0, 0);
        continue;
      }
      for (Index b = 0; b < tr.batch(); ++b) {
        x = tr.states[i].col(b);
        u = tr.controls[i].col(b);
        sim.step(x, u, next);
        sim.vjp(x, u, next, &lx, &lu);  // λ = x_{n+1}: any vector does
        sum += next(0) + lx(0) + lu(0);
      }
    }
    best = std::min(best, now_ms() - start);
  }
  volatile double sink = static_cast<double>(sum);
  (void)sink;
  return best * 1e6 / static_cast<double>(tr.steps() * tr.batch());
}

/// The trainer options of every row's trainers: batch 8, the row's method, `threads`.
inline sbptt::TrainerOptions row_trainer_options(
    Method method, Index threads,
    sbptt::SweepThreading sweep_threading = sbptt::SweepThreading::Timed) {
  sbptt::TrainerOptions options;
  options.method = method;
  options.batch = 8;
  options.threads = threads;
  options.sweep_threading = sweep_threading;
  return options;
}

/// Adam with the paper's rate, 1e-3.
template <class S>
sbptt::Adam<S> row_optimizer() {
  return sbptt::Adam<S>(sbptt::AdamOptions<S>{S(1e-3)});
}

/// A trainer of a row with a copy of the row's network of its own, counted by a
/// `CountingNetwork` of its own (Adam, lr 1e-3, batch 8). The trainer keeps references to both,
/// so they live beside it, and the object is built in place and never moved.
template <class Sim, class Loss>
struct CountedTrainer {
  using S = typename Sim::Scalar;
  Network<S> net;
  CountingNetwork<S> counted{net};
  sbptt::Trainer<Sim, CountingNetwork<S>, Loss, sbptt::Adam<S>> trainer;

  CountedTrainer(const Sim& sim, const Network<S>& initial, const sbptt::Objective<Loss>& objective,
                 Index steps, Method method, Index threads,
                 sbptt::SweepThreading sweep_threading = sbptt::SweepThreading::Timed)
      : net(initial),
        trainer(sim, counted, objective, steps, row_optimizer<S>(),
                row_trainer_options(method, threads, sweep_threading)) {}
  CountedTrainer(const CountedTrainer&) = delete;
  CountedTrainer& operator=(const CountedTrainer&) = delete;
};

/// A trainer of a row's network, uncounted (its copy for the evaluation must own its
/// parameters, and a `CountingNetwork` is a view), whose epochs are evaluated beside the next
/// one's training as `run_training` does with `evaluate_beside`: `epoch()` trains one epoch
/// while the second thread evaluates the parameters the epoch before left. `epoch_alone()` is
/// the same trainer's plain 1-thread epoch, which the speed-up is taken against, so that both
/// sides run the same uncounted network.
template <class Sim, class Loss>
struct TrainerBeside {
  using S = typename Sim::Scalar;
  using TrainerT = sbptt::Trainer<Sim, Network<S>, Loss, sbptt::Adam<S>>;
  Network<S> net;
  TrainerT trainer;
  sbptt::EvaluationBeside<TrainerT> evaluation{trainer};
  sbptt::Vector<S> evaluated;
  sbptt::EpochRecord record;
  std::vector<sbptt::NonFiniteEvent> events;

  TrainerBeside(const Sim& sim, const Network<S>& initial, const sbptt::Objective<Loss>& objective,
                Index steps, Method method)
      : net(initial),
        trainer(sim, net, objective, steps, row_optimizer<S>(), row_trainer_options(method, 1)) {}
  TrainerBeside(const TrainerBeside&) = delete;
  TrainerBeside& operator=(const TrainerBeside&) = delete;

  void epoch(const Matrix<S>& train, const Matrix<S>& test) {
    evaluated = net.params();
    events.clear();
    evaluation.run(evaluated, train, test, record, events,
                   [&] { trainer.train_epoch(train, test, false); });
  }
  void epoch_alone(const Matrix<S>& train, const Matrix<S>& test) {
    trainer.train_epoch(train, test);
  }
};

/// One row: warm-up + timed epochs at 1 and at N threads, then the host's measures of threads.
/// Everything the row's ratios compare is timed in turn, one of each per repeat, so that both
/// sides of a ratio see the machine of the same minute: the 1- and the N-thread epochs, the
/// peak, and for a C row the R epochs of a trainer of its own. The host's speed drifts
/// (docs/benchmark-runs-intel.md): timed one after the other, a row whose 1-thread epochs fell
/// in a slow minute showed 2.43× on two threads, and a peak measured at the start of a run
/// was 131 GFLOP/s in a run whose epochs were slower than those of the next run, whose peak was
/// 90 (twenty-sixth run).
template <class Sim, class Loss>
RowResult measure(const Settings& settings, const Sim& sim,
                  const Network<typename Sim::Scalar>& initial,
                  const sbptt::Objective<Loss>& objective, Index steps,
                  const Matrix<typename Sim::Scalar>& train,
                  const Matrix<typename Sim::Scalar>& test, Method method) {
  using Counted = CountedTrainer<Sim, Loss>;
  RowResult r;
  const auto epoch = [&](Counted& row_trainer) { row_trainer.trainer.train_epoch(train, test); };
  const auto evaluation = [&](Counted& row_trainer) {
    row_trainer.trainer.engine().evaluate(train);
    row_trainer.trainer.engine().evaluate(test);
  };
  Counted alone(sim, initial, objective, steps, method, 1);
  epoch(alone);  // warm-up: buffers sized, pages touched
  // The row's memory is one trainer's, not all of theirs: read before the others are built,
  // after the warm-up has sized the buffers (the engine allocates nothing after its first
  // batch: tests/test_bptt_no_malloc.cpp).
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  r.rss_kib = static_cast<double>(usage.ru_maxrss);
  // What the threads the system will not start (ulimit -u, a pids limit) say leads with the
  // flag that asked for them.
  const std::string threads_flag = "--threads " + std::to_string(settings.threads);
  std::optional<Counted> threaded;  // none with one thread
  std::optional<TrainerBeside<Sim, Loss>> beside;  // none with one thread
  if (settings.threads > 1) {
    sbptt::detail::prefixing_errors(threads_flag, [&] {
      threaded.emplace(sim, initial, objective, steps, method, settings.threads,
                       settings.sweep_threading);
      epoch(*threaded);  // its warm-up
      beside.emplace(sim, initial, objective, steps, method);
      beside->epoch(train, test);  // its warm-up
    });
  }
  std::optional<Counted> regular;  // a C row's R trainer
  if (method == Method::Combined) {
    regular.emplace(sim, initial, objective, steps, Method::Regular, 1);
    epoch(*regular);  // its warm-up
  }
  alone.counted.reset();
  r.ms_epoch = r.ms_threads = r.ms_regular = r.ms_evaluation = r.ms_evaluation_threads =
      r.ms_beside = r.ms_beside_alone = 1e300;
  const auto keep_fastest = [](double& best, auto&& work) {
    best = std::min(best, timed_ms(work));
  };
  const auto keep_best = [&](double& best, Counted& row_trainer) {
    keep_fastest(best, [&] { epoch(row_trainer); });
  };
  long long untimed_macs = 0;  // not the timed epochs' work: kept out of the GFLOP count
  const auto uncounted = [&](auto&& work) {
    const long long before = alone.counted.macs();
    work();
    untimed_macs += alone.counted.macs() - before;
  };
  const sbptt::SweepTally tally_before =
      threaded ? threaded->trainer.engine().sweep_tally() : sbptt::SweepTally{};
  for (int repeat = 0; repeat < settings.repeats; ++repeat) {
    keep_best(r.ms_epoch, alone);
    if (regular) keep_best(r.ms_regular, *regular);  // right after the C epoch it is set against
    if (threaded) {
      keep_best(r.ms_threads, *threaded);
      uncounted([&] { keep_fastest(r.ms_evaluation, [&] { evaluation(alone); }); });
      keep_fastest(r.ms_evaluation_threads, [&] { evaluation(*threaded); });
      keep_fastest(r.ms_beside, [&] { beside->epoch(train, test); });
      keep_fastest(r.ms_beside_alone, [&] { beside->epoch_alone(train, test); });
    }
    r.peak_gflops = std::max(r.peak_gflops, measure_peak<typename Sim::Scalar>());
    // The first epoch after the peak's products ran about 1% slower than one after an epoch,
    // which is how epochs follow each other in training: timed first in each repeat, a C
    // epoch made guidance's C/R 1.293–1.308, timed after the R epoch 1.275–1.290; with this
    // untimed epoch between, 1.283–1.292 (docs/benchmark-runs.md, sixtieth run).
    if (repeat + 1 < settings.repeats) uncounted([&] { epoch(alone); });
  }
  if (!threaded) {
    r.ms_threads = r.ms_epoch;
    r.ms_evaluation = r.ms_evaluation_threads = r.ms_beside = r.ms_beside_alone = 0;
  }
  if (!regular) r.ms_regular = 0;
  r.gflop = 2.0 * static_cast<double>(alone.counted.macs() - untimed_macs) /
            settings.repeats / 1e9;
  r.sim_ns = simulator_ns(sim, alone.trainer.engine());
  r.trajectory_bytes = static_cast<double>(alone.trainer.engine().trajectory().bytes());
  if (threaded) {
    const sbptt::SweepTally tally = threaded->trainer.engine().sweep_tally();
    r.sweeps_threaded = tally.threaded - tally_before.threaded;
    r.sweeps_alone = tally.alone - tally_before.alone;
    sbptt::detail::prefixing_errors(threads_flag + " (--threads 1 runs no host probes)", [&] {
      r.round_trip_ns = cross_core_round_trip_ns();
      r.other_core_read_ratio = other_core_read_ratio();
      r.copies_ratio =
          concurrent_copies_ratio(settings.threads, settings.repeats, [&](auto&& rounds) {
            Counted copy(sim, initial, objective, steps, method, 1);
            rounds([&] { epoch(copy); });
          });
    });
  }
  r.ok = 1;
  return r;
}

/// Glorot-uniform MLP 2×100 tanh with the last kernel zeroed (the paper's cart pole/guidance).
template <class S>
Network<S> paper_mlp(Index inputs, Index outputs) {
  auto net = Network<S>::mlp(inputs, {100, 100}, outputs);
  sbptt::Rng rng(42);
  sbptt::GlorotOptions options;
  options.zero_last_kernel = true;
  sbptt::glorot_uniform(net, rng, options);
  return net;
}

/// The paper's quantum CNN, for Nx grid points: conv 2→60 k3 s2 tanh, conv 60→60 k3 s2 tanh,
/// dense → 1 (Nx = 32: 15 and 7 positions, 11,701 parameters).
template <class S>
Network<S> paper_cnn(Index nx) {
  const sbptt::Conv1d first{nx, 2, 60, 3, 2, sbptt::Activation::Tanh};
  const sbptt::Conv1d second{first.output_length(), 60, 60, 3, 2, sbptt::Activation::Tanh};
  Network<S> net({first, second, sbptt::Dense{second.output_dim(), 1}});
  sbptt::Rng rng(42);
  sbptt::glorot_uniform(net, rng);
  return net;
}

using sbptt::examples::Route;

/// The cart pole's row, its simulator built by route R (data and objective from the shipped one).
template <class S, int Poles, Route R = Route::Analytic>
RowResult cartpole_row(const Settings& settings, Method method) {
  const sbptt::CartPole<S, Poles> shipped;
  const auto sim = sbptt::examples::cartpole_route<S, Poles, R>();
  sbptt::Rng rng(42);
  const Matrix<S> train = sbptt::cartpole_initial_states(shipped, rng, 256);
  const Matrix<S> test = sbptt::cartpole_initial_states(shipped, rng, 256);
  const auto net = paper_mlp<S>(sim.state_dim(), 1);
  RowResult r = measure(settings, sim, net, sbptt::cartpole_objective<S, Poles>(),
                        shipped.steps(), train, test, method);
  r.nx = sim.state_dim();
  r.steps = shipped.steps();
  r.params = net.num_params();
  return r;
}

template <class S, Route R = Route::Analytic>
RowResult guidance_row(const Settings& settings, Method method) {
  const sbptt::GuidanceByRepulsion<S, 2, 4> shipped;
  const auto sim = sbptt::examples::guidance_route<S, R>();
  sbptt::Rng rng(42);
  const Matrix<S> train = sbptt::guidance_initial_states(shipped, rng, 256);
  const Matrix<S> test = sbptt::guidance_initial_states(shipped, rng, 256);
  const auto net = paper_mlp<S>(sim.state_dim(), sim.control_dim());
  RowResult r = measure(settings, sim, net, sbptt::guidance_objective(shipped, 0.1),
                        shipped.steps(), train, test, method);
  r.nx = sim.state_dim();
  r.steps = shipped.steps();
  r.params = net.num_params();
  return r;
}

template <class S, int Nx>
RowResult quantum_row(const Settings& settings, Method method) {
  const sbptt::Schrodinger1D<S, Nx> sim;
  sbptt::Rng rng(42);
  const Matrix<S> train = sim.initial_states(rng, 256);
  const Matrix<S> test = sim.initial_states(rng, 256);
  const auto net = paper_cnn<S>(Nx);
  RowResult r = measure(settings, sim, net, sbptt::quantum_objective(sim, 4), sim.steps(), train,
                        test, method);
  r.nx = Nx;
  r.steps = sim.steps();
  r.params = net.num_params();
  return r;
}

/// Runs `body` in a child process and returns what it wrote into the pipe.
inline RowResult in_child(const std::function<RowResult()>& body) {
  int fds[2];
  if (pipe(fds) != 0) throw sbptt::IoError("bench: pipe() failed");
  std::fflush(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) throw sbptt::IoError("bench: fork() failed");
  if (pid == 0) {
    // A bench stopped by a signal (kill, a scheduler) takes its measuring child with it, which
    // would otherwise burn a core to the end of its row.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(1);  // it died before the line above
    close(fds[0]);
    RowResult r;
    try {
      r = body();
    } catch (const std::exception& e) {
      std::snprintf(r.error, sizeof r.error, "%s", e.what());
    }
    const ssize_t written = write(fds[1], &r, sizeof r);
    _exit(written == static_cast<ssize_t>(sizeof r) ? 0 : 1);
  }
  close(fds[1]);
  RowResult r;
  const ssize_t got = read(fds[0], &r, sizeof r);
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (got != static_cast<ssize_t>(sizeof r)) {
    r = RowResult{};
    std::snprintf(r.error, sizeof r.error, "child process failed (status %d)", status);
  }
  return r;
}

}  // namespace bench
