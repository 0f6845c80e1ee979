#pragma once
/// \file What a checkpoint of `run_training` records of its run, and must share with the run
/// that resumes it (docs/training.md, "Settings must match"): the caller's
/// `RunSettings::identity`, then the trainer's options, the scalar type, the evaluation
/// schedule, fingerprints of the sets and the initial parameters, the horizon, the objective's
/// timing and weights, and Adam's constants. The state loss's own parameters (a target) and
/// the simulator's are the caller's to add: no concept makes them readable.
#include <cstddef>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/train/checkpoint.hpp"
#include "sbptt/train/fingerprint.hpp"
#include "sbptt/train/run_settings.hpp"
#include "sbptt/train/trainer.hpp"

namespace sbptt::detail {

/// An optimizer whose state a checkpoint can hold (Adam).
template <class O>
concept AdamLike = requires(O o, Vector<typename O::Scalar> v) {
  o.first_moment();
  o.second_moment();
  o.iterations();
  o.options().learning_rate;
  o.restore(v, v, Index{});
};

/// The settings of a run of `trainer` on `train` and `test`; throws `InvalidArgument` for a
/// caller's setting the checkpoint could not read back.
template <class TrainerT>
[[nodiscard]] std::vector<RunSetting> run_identity(
    TrainerT& trainer, const Matrix<typename TrainerT::Scalar>& train,
    const Matrix<typename TrainerT::Scalar>& test, const RunSettings& settings, BestBy best_by) {
  using Scalar = typename TrainerT::Scalar;
  using Optimizer = std::remove_cvref_t<decltype(trainer.optimizer())>;
  const TrainerOptions& o = trainer.options();
  const auto& objective = trainer.engine().objective();
  std::vector<RunSetting> identity = settings.identity;
  for (RunSetting s : std::vector<RunSetting>{
           {"method", std::string(label(o.method))},
           {"clip", to_string(o.clip)},
           {"clip_threshold", exact(o.clip_threshold)},
           {"batch", std::to_string(o.batch)},
           {"shuffle", o.shuffle ? "yes" : "no"},
           {"shuffle_seed", std::to_string(o.shuffle_seed)},
           {"truncation", std::to_string(o.truncation)},
           {"on_non_finite", o.on_non_finite == NonFinitePolicy::Stop ? "stop" : "skip-batch"},
           {"scalar", sizeof(Scalar) == sizeof(float) ? "float" : "double"},
           {"evaluate_every", std::to_string(settings.evaluate_every)},
           {"best_by", best_by == BestBy::TestLoss ? "test loss" : "train loss"},
           {"patience", std::to_string(settings.patience)},
           {"train set", fingerprint(train)},
           {"test set", fingerprint(test)},
           {"initial parameters", fingerprint(trainer.controller().params())},
           {"steps", std::to_string(trainer.engine().steps())},
           {"loss_timing", objective.timing == LossTiming::Final ? "final" : "continuous"},
           {"step_weight", exact(objective.step_weight)},
           {"control_weight", exact(objective.control_weight)}})
    identity.push_back(std::move(s));
  if constexpr (AdamLike<Optimizer>) {
    const auto& adam = trainer.optimizer().options();
    identity.push_back({"learning_rate", exact(adam.learning_rate)});
    identity.push_back({"beta1", exact(adam.beta1)});
    identity.push_back({"beta2", exact(adam.beta2)});
    identity.push_back({"epsilon", exact(adam.epsilon)});
  }
  // The checkpoint holds a line "setting name=value" each, read back as one setting per name.
  for (std::size_t i = 0; i < identity.size(); ++i) {
    const RunSetting& s = identity[i];
    const bool own = i < settings.identity.size();
    require(!s.name.empty() && s.name.find_first_of("=\n") == std::string::npos &&
                s.value.find('\n') == std::string::npos,
            "run_training: RunSettings::identity has setting '", s.name, "' = '", s.value,
            "'; expected a name without '=' or a line break, and a value of one line");
    for (std::size_t j = 0; j < i; ++j)
      require(identity[j].name != s.name, "run_training: setting '", s.name, "' is in ",
              own ? "RunSettings::identity twice"
                  : "RunSettings::identity and among run_training's own settings",
              "; expected each name once");
  }
  return identity;
}

}  // namespace sbptt::detail
