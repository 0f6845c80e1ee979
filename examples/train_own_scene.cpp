// A user's own scene (the point mass of point_mass.hpp) trained with the library's driver:
// combined update, a test set, a CSV log, the best parameters kept, early stop, checkpoints.
// SIGINT, SIGTERM, SIGHUP or SIGXCPU stops it after the current epoch with its work saved (exit
// 128 + the signal). Rerun it after a stop or a kill and it resumes from the checkpoint, and says
// so. A template to copy: it and point_mass.hpp need only the installed headers.
//   train_own_scene [DIRECTORY]      (writes log.csv, run.checkpoint, best.params there;
//                                     in the working directory without one)
#include <csignal>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <string>

#include "point_mass.hpp"

namespace {

constexpr const char* kUsage = "usage: train_own_scene [DIRECTORY]  (an existing directory; "
                               "log.csv, run.checkpoint and best.params go there)";

/// `code`, or 1 in place of 0 if stdout could not take what was printed (a full disk): the
/// losses (or the usage) are part of the result.
int with_stdout_checked(int code) {
  if (code != 0 || (std::fflush(stdout) == 0 && std::ferror(stdout) == 0)) return code;
  std::fprintf(stderr, "train_own_scene: standard output was not written in full\n");
  return 1;
}

/// The run of the file comment with its files in `dir`; returns the exit code.
int run_in(const std::filesystem::path& dir) {
  using Loss = sbptt::SquaredDistanceLoss<PointMass::State>;
  const PointMass sim;
  auto network = sbptt::Network<double>::mlp(2, {32, 32}, 1);
  sbptt::Rng rng(1);
  sbptt::glorot_uniform(network, rng, {.zero_last_kernel = true});
  sbptt::Matrix<double> train(2, 64), test(2, 16);
  for (auto* set : {&train, &test})
    for (sbptt::Index i = 0; i < set->size(); ++i) (*set)(i) = rng.uniform(-1, 1);

  const PointMass::State target = PointMass::State::Zero();
  sbptt::Trainer trainer(sim, network, sbptt::Objective<Loss>{Loss{target}}, 30,
                         sbptt::Adam<double>({.learning_rate = 3e-3}),
                         {.method = sbptt::Method::Combined, .batch = 16, .shuffle = true});
  const sbptt::StopSignals stop("train_own_scene");
  const auto digits = [](double value) {  // all 17, so that any change of a constant counts
    char text[32];
    std::snprintf(text, sizeof text, "%.17g", value);
    return std::string(text);
  };
  const auto result = sbptt::run_training(
      trainer, train, test,
      {.epochs = 200, .evaluate_every = 5, .patience = 10, .restore_best = true,
       .log_csv = (dir / "log.csv").string(), .checkpoint = (dir / "run.checkpoint").string(),
       .save_params = (dir / "best.params").string(),
       // What the checkpoint cannot read from the trainer (it records the horizon and the
       // objective's weights itself): the scene's constants and the loss's target, so that a
       // run of an edited scene starts over.
       .identity = {{"dt", digits(sim.model().dt)},
                    {"friction", digits(sim.model().friction)},
                    {"target", digits(target(0)) + " " + digits(target(1))}}},
      {.on_resume = [](long epoch) {
         std::printf("resumed from the checkpoint of epoch %ld\n", epoch);
       },
       .on_epoch = [](const sbptt::EpochRecord& r) {
         if (r.test_loss && r.epoch % 50 == 0)
           std::printf("epoch %3ld  test loss %.3e\n", r.epoch, *r.test_loss);
       },
       .should_stop = [&](const sbptt::EpochRecord&) { return stop.requested(); }});
  const std::string saved =
      result.saved_params.empty()
          ? std::string()
          : "; the best parameters so far were saved to '" + result.saved_params + "'";
  switch (result.end) {
    case sbptt::RunEnd::NonFinite:
      std::fprintf(stderr, "train_own_scene: stopped: %s\n",
                   sbptt::describe(*result.stop_event).c_str());
      return 3;
    case sbptt::RunEnd::OutputFailed:
      std::fprintf(stderr, "train_own_scene: %s%s\n", result.output_error.c_str(), saved.c_str());
      return 1;
    case sbptt::RunEnd::Requested:
      std::fprintf(stderr, "train_own_scene: stopped by %s after epoch %ld; run it again to "
                   "resume%s\n", sbptt::signal_name(stop.signal()), result.epochs, saved.c_str());
      return 128 + stop.signal();
    case sbptt::RunEnd::Finished:
    case sbptt::RunEnd::EarlyStop:
      std::printf("best test loss %.3e in epoch %ld of %ld\n", result.best_loss,
                  result.best_epoch, result.epochs);
      return 0;
  }
  return 1;  // unreachable: every RunEnd is handled above
}

}  // namespace

int main(int argc, char** argv) {
  // Past a file-size limit (ulimit -f) the default SIGXFSZ, and with the reader of stdout gone
  // (`| head`) the default SIGPIPE, kill the program silently with its files unwritten;
  // ignored, the write fails and the run reports it (exit 1, the parameters still saved).
  // Written out here, not taken from examples/common, so that a copy of this file and
  // point_mass.hpp builds against the installed headers alone.
  std::signal(SIGXFSZ, SIG_IGN);
  std::signal(SIGPIPE, SIG_IGN);
  const std::string argument = argc > 1 ? argv[1] : ".";
  if (argument == "--help") {
    std::printf("%s\n", kUsage);
    return with_stdout_checked(0);
  }
  if (argc > 2) {
    std::fprintf(stderr, "train_own_scene: %d arguments, expected at most one DIRECTORY (%s)\n",
                 argc - 1, kUsage);
    return 2;
  }
  if (argument.starts_with('-')) {
    std::fprintf(stderr, "train_own_scene: unknown flag '%s' (%s)\n", argument.c_str(), kUsage);
    return 2;
  }
  std::error_code error;
  if (argument.empty() || !std::filesystem::is_directory(argument, error)) {
    std::fprintf(stderr, "train_own_scene: DIRECTORY = '%s', expected an existing directory (%s)\n",
                 argument.c_str(), kUsage);
    return 2;
  }
  try {
    return with_stdout_checked(run_in(argument));
  } catch (const std::exception& e) {  // the library's errors name the file and what was wrong
    std::fprintf(stderr, "train_own_scene: %s\n", e.what());
    return 1;
  }
}
