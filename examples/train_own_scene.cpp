// A user's own scene (the point mass of point_mass.hpp) trained with the library's driver:
// combined update, a test set, a CSV log, the best parameters kept, early stop, checkpoints.
// Rerun it after a kill and it resumes from the checkpoint.
//   train_own_scene [DIRECTORY]      (writes log.csv, run.checkpoint, best.params there)
#include <cstdio>
#include <string>

#include "point_mass.hpp"

int main(int argc, char** argv) {
  const std::string dir = argc > 1 ? std::string(argv[1]) + "/" : "";
  using Loss = sbptt::SquaredDistanceLoss<PointMass::State>;
  const PointMass sim;
  auto network = sbptt::Network<double>::mlp(2, {32, 32}, 1);
  sbptt::Rng rng(1);
  sbptt::glorot_uniform(network, rng, {.zero_last_kernel = true});
  sbptt::Matrix<double> train(2, 64), test(2, 16);
  for (auto* set : {&train, &test})
    for (sbptt::Index i = 0; i < set->size(); ++i) (*set)(i) = rng.uniform(-1, 1);

  sbptt::Trainer trainer(sim, network, sbptt::Objective<Loss>{Loss{PointMass::State::Zero()}}, 30,
                         sbptt::Adam<double>({.learning_rate = 3e-3}),
                         {.method = sbptt::Method::Combined, .batch = 16, .shuffle = true});
  const auto result = sbptt::run_training(
      trainer, train, test,
      {.epochs = 200, .evaluate_every = 5, .patience = 10, .restore_best = true,
       .log_csv = dir + "log.csv", .checkpoint = dir + "run.checkpoint",
       .save_params = dir + "best.params"},
      {.on_epoch = [](const sbptt::EpochRecord& r) {
        if (r.test_loss && r.epoch % 50 == 0)
          std::printf("epoch %3ld  test loss %.3e\n", r.epoch, *r.test_loss);
      }});
  std::printf("best test loss %.3e in epoch %ld of %ld\n", result.best_loss, result.best_epoch,
              result.epochs);
  return result.end == sbptt::RunEnd::Finished || result.end == sbptt::RunEnd::EarlyStop ? 0 : 1;
}
