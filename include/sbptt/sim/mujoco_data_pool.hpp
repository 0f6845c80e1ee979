#pragma once
/// \file The `mjData`s that `MujocoSimulator`'s calls lease, MuJoCo's warnings read off them,
/// and the record of the calls MuJoCo refused (`MujocoRefusals`), shared by the copies of a
/// simulator.
///
/// A refusal is a call (a step, or the differences of the Jacobians) that MuJoCo would not
/// take from its input or did not finish as asked (see `mujoco_failures`), and that the
/// simulator therefore answered with NaN. Its reason is the warning MuJoCo raised ("its
/// contact buffer is full (increase nconmax above 100)"), else the value beyond MuJoCo's bound
/// of 1e10. A NaN in the input is not recorded: it is no refusal of MuJoCo's but a NaN from
/// elsewhere, which the engine's report names.
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include <mujoco/mujoco.h>

#include "sbptt/core/error.hpp"

namespace sbptt {

/// The calls a `MujocoSimulator` refused since the last `take_refusals()`.
struct MujocoRefusals {
  long count = 0;     ///< calls answered with NaN because MuJoCo refused them
  std::string first;  ///< why the first of them was refused; empty when count = 0
};

/// "MuJoCo refused 3 calls (steps or their derivatives); the first: <why>", "MuJoCo refused a
/// call (a step or its derivatives): <why>", or "" for none.
[[nodiscard]] inline std::string describe(const MujocoRefusals& refusals) {
  if (refusals.count == 0) return {};
  if (refusals.count == 1)
    return "MuJoCo refused a call (a step or its derivatives): " + refusals.first;
  return detail::concat("MuJoCo refused ", refusals.count,
                        " calls (steps or their derivatives); the first: ", refusals.first);
}

namespace detail {

/// The warnings after which MuJoCo has reset or truncated the step it was asked to take, those
/// after which it resets first: a reset zeroes every record and recomputes the model's rest
/// state, so a full contact buffer there is raised after the warning that caused the reset.
constexpr int mujoco_failures[] = {mjWARN_BADQPOS, mjWARN_BADQVEL,     mjWARN_BADQACC,
                                   mjWARN_BADCTRL, mjWARN_CONTACTFULL, mjWARN_CNSTRFULL};

/// Marks every warning as raised once already, with no info. MuJoCo's `mj_warning` prints
/// (and appends to MUJOCO_LOG.TXT in the working directory) only a warning's first
/// occurrence in an mjData, so this keeps a library call silent; any warning then changes
/// `lastinfo`, and `mj_resetData` zeroes the record, so `mujoco_failure` still sees it.
inline void arm_mujoco_warnings(mjData& data) {
  for (auto& warning : data.warning) {
    warning.number = 1;
    warning.lastinfo = -1;
  }
}

/// Why MuJoCo did not take a step as asked, after `warning` with its info (a DOF, an actuator
/// or a buffer's size). In words of our own: `mju_warningText` writes one static buffer that
/// MuJoCo's own warnings write too, from any thread.
inline std::string failure_text(int warning, int info) {
  const char* bad = "NaN, Inf or a value beyond 1e10 in ";
  switch (warning) {
    case mjWARN_BADQPOS: return concat(bad, "qpos at DOF ", info, ", so it reset the state");
    case mjWARN_BADQVEL: return concat(bad, "qvel at DOF ", info, ", so it reset the state");
    case mjWARN_BADQACC: return concat(bad, "qacc at DOF ", info, ", so it reset the state");
    case mjWARN_BADCTRL: return concat(bad, "ctrl at actuator ", info);
    case mjWARN_CONTACTFULL:
      return concat("its contact buffer is full (increase nconmax above ", info, ")");
    case mjWARN_CNSTRFULL:
      return concat("its constraint buffer is full (increase njmax above ", info, ")");
    default: return concat("MuJoCo warning ", warning, " (info ", info, ")");
  }
}

/// Why MuJoCo did not take the step it was last asked for in `data` (the first of
/// `mujoco_failures` raised since `arm_mujoco_warnings`), or "". A record that a reset zeroed
/// (number 0) was not raised: the warning that caused the reset is recorded after it.
inline std::string mujoco_failure(const mjData& data) {
  bool reset = false;
  for (const int kind : mujoco_failures) {
    const mjWarningStat& warning = data.warning[kind];
    if (warning.number == 0) {
      reset = true;
    } else if (warning.number != 1 || warning.lastinfo != -1) {
      return failure_text(kind, warning.lastinfo);
    }
  }
  return reset ? "MuJoCo reset its data without a warning" : "";
}

/// One `mjData` with the row-major Jacobian buffers of `mjd_transitionFD`, and the probes of
/// the whole-step differences that replace it for RK4.
struct MujocoSlot {
  struct DataDeleter {
    void operator()(mjData* released) const { mj_deleteData(released); }
  };
  std::unique_ptr<mjData, DataDeleter> data;
  std::vector<mjtNum> state_jacobian, control_jacobian;  ///< n × n and n × nu, row-major
  std::vector<mjtNum> probe;                            ///< (x, u) moved: n + nu
  std::vector<mjtNum> plus, minus;                      ///< the probes' next states: n
};

/// A pool of `MujocoSlot`s: `lease()` hands out a slot no other caller holds, and takes it
/// back when the lease ends. Grows to the largest number of concurrent callers.
class MujocoDataPool {
public:
  explicit MujocoDataPool(std::shared_ptr<const mjModel> model) : model_(std::move(model)) {}

  class Lease {
  public:
    Lease(MujocoDataPool& pool, std::unique_ptr<MujocoSlot> slot)
        : pool_(&pool), slot_(std::move(slot)) {}
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    Lease(Lease&&) = delete;
    Lease& operator=(Lease&&) = delete;
    ~Lease() { pool_->give_back(std::move(slot_)); }
    MujocoSlot& operator*() const { return *slot_; }
    MujocoSlot* operator->() const { return slot_.get(); }

  private:
    MujocoDataPool* pool_;
    std::unique_ptr<MujocoSlot> slot_;
  };

  [[nodiscard]] Lease lease() {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!free_.empty()) {
        auto slot = std::move(free_.back());
        free_.pop_back();
        return {*this, std::move(slot)};
      }
    }
    auto slot = std::make_unique<MujocoSlot>();
    slot->data.reset(mj_makeData(model_.get()));
    require(slot->data != nullptr, "MujocoSimulator: mj_makeData could not allocate an mjData");
    const std::size_t n =
        2 * static_cast<std::size_t>(model_->nv) + static_cast<std::size_t>(model_->na);
    slot->state_jacobian.resize(n * n);
    slot->control_jacobian.resize(n * static_cast<std::size_t>(model_->nu));
    slot->probe.resize(n + static_cast<std::size_t>(model_->nu));
    slot->plus.resize(n);
    slot->minus.resize(n);
    return {*this, std::move(slot)};
  }

  /// Notes one refused call and why (kept for the first since the last `take_refusals`).
  void record_refusal(std::string why) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (refusals_.count++ == 0) refusals_.first = std::move(why);
  }

  /// The refusals since the last call, which are then forgotten.
  [[nodiscard]] MujocoRefusals take_refusals() {
    const std::lock_guard<std::mutex> lock(mutex_);
    return std::exchange(refusals_, MujocoRefusals{});
  }

private:
  void give_back(std::unique_ptr<MujocoSlot> slot) {
    const std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(std::move(slot));
  }

  std::shared_ptr<const mjModel> model_;
  std::mutex mutex_;
  std::vector<std::unique_ptr<MujocoSlot>> free_;
  MujocoRefusals refusals_;
};

}  // namespace detail

}  // namespace sbptt
