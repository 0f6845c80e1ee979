// Why the MuJoCo adapter (include/sbptt/sim/mujoco.hpp) refused a call, against MuJoCo's own
// record of its warnings after a plain mj_step from the same state.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "sbptt/sim/mujoco.hpp"

#include "support/mujoco_models.hpp"

using namespace sbptt;
using sbptt::testing::mujoco_cartpole;
using sbptt::testing::write_temp_model;

TEST_CASE("mujoco: each refused call says why, from MuJoCo's own record of its warnings",
          "[sim][mujoco]") {
  static int printed = 0;
  mju_user_warning = [](const char*) { ++printed; };
  // Two spheres on slide joints resting in a plane, and room for one contact: MuJoCo drops
  // the second contact with a warning and carries on, a step with a missing contact. The
  // motor's gear lets a control within MuJoCo's bound give an acceleration beyond it.
  const std::string file = write_temp_model(
      "contact_full.xml",
      "<mujoco><size nconmax='1'/><worldbody><geom type='plane' size='5 5 .1'/>"
      "<body pos='0 0 0.05'><joint name='a' type='slide' axis='0 0 1'/><geom size='0.1'/></body>"
      "<body pos='1 0 0.05'><joint name='b' type='slide' axis='0 0 1'/><geom size='0.1'/></body>"
      "</worldbody><actuator><motor joint='a' gear='1e6'/></actuator></mujoco>");
  const MujocoModelPtr model = load_mujoco_model(file);
  std::filesystem::remove(file);
  /// The truth: MuJoCo's own records after a plain mj_step from the rest state with `control`.
  const auto plain_step = [&](double control) {
    mjData* d = mj_makeData(model.get());
    d->ctrl[0] = control;
    mj_step(model.get(), d);
    std::vector<mjWarningStat> records(d->warning, d->warning + mjNWARNING);
    mj_deleteData(d);
    printed = 0;  // MuJoCo's own prints of them
    return records;
  };
  const auto at_rest = plain_step(0.0);
  REQUIRE(at_rest[mjWARN_CONTACTFULL].number == 1);
  REQUIRE(at_rest[mjWARN_CONTACTFULL].lastinfo == 1);  // nconmax
  const std::string contact_full = "its contact buffer is full (increase nconmax above 1)";
  const MujocoSimulator<double> spheres(*model);
  const MujocoSimulator<double> copy = spheres;  // copies share the record
  CHECK(spheres.take_refusals().count == 0);
  CHECK(describe(spheres.take_refusals()).empty());
  Vector<double> next;
  const Vector<double> u = Vector<double>::Zero(1);
  spheres.step(spheres.initial_state(), u, next);
  CHECK(next.array().isNaN().all());
  copy.step(spheres.initial_state(), u, next);
  Matrix<double> a, b;
  spheres.jacobians(spheres.initial_state(), u, a, b);
  CHECK(a.array().isNaN().all());
  const MujocoRefusals refusals = copy.take_refusals();
  CHECK(refusals.count == 3);
  CHECK(refusals.first == contact_full);
  CHECK(describe(refusals) ==
        "MuJoCo refused 3 calls (steps or their derivatives); the first: " + contact_full);
  CHECK(spheres.take_refusals().count == 0);  // taken
  CHECK(printed == 0);
  // An acceleration beyond the bound: MuJoCo warns, resets (zeroing every record) and
  // recomputes the rest state, where the contact buffer overflows again. The cause is the
  // acceleration. (MuJoCo prints the warnings raised after its reset; no call can stop it.)
  const auto pushed = plain_step(1e5);
  REQUIRE(pushed[mjWARN_BADQACC].number >= 1);
  REQUIRE(pushed[mjWARN_CONTACTFULL].number >= 1);
  spheres.step(spheres.initial_state(), Vector<double>::Constant(1, 1e5), next);
  CHECK(next.array().isNaN().all());
  CHECK(spheres.take_refusals().first ==
        detail::concat("NaN, Inf or a value beyond 1e10 in qacc at DOF ",
                       pushed[mjWARN_BADQACC].lastinfo, ", so it reset the state"));
  printed = 0;
  // A value MuJoCo refuses in the input is named; a NaN in it is not MuJoCo's doing.
  const auto cart = mujoco_cartpole(1, 0.01);
  const Vector<double> good = (Vector<double>(4) << 0.1, 3.0, 0.2, -0.5).finished();
  Vector<double> x = good;
  x(1) = std::nan("");
  cart.step(x, Vector<double>::Constant(1, 1.0), next);
  CHECK(cart.take_refusals().count == 0);
  x(1) = 2e10;
  cart.step(x, Vector<double>::Constant(1, 1.0), next);
  CHECK(describe(cart.take_refusals()) ==
        "MuJoCo refused a call (a step or its derivatives): the state's qpos[1] is 2e+10, beyond "
        "MuJoCo's bound of 1e+10");
  x(1) = 0.1;
  x(3) = 3e10;
  cart.step(x, Vector<double>::Constant(1, 1.0), next);
  CHECK(cart.take_refusals().first ==
        "the state's qvel[1] is 3e+10, beyond MuJoCo's bound of 1e+10");
  cart.step(good, Vector<double>::Constant(1, -3e10), next);
  CHECK(cart.take_refusals().first ==
        "the control's ctrl[0] is -3e+10, beyond MuJoCo's bound of 1e+10");
  // An acceleration beyond the bound (see the test above), as a plain mj_step from the same
  // state records it.
  x = good;
  x(3) = 1e6;
  {
    mjData* d = mj_makeData(&cart.model());
    for (int i = 0; i < 2; ++i) {
      d->qpos[i] = x(i);
      d->qvel[i] = x(2 + i);
    }
    d->ctrl[0] = 1.0;
    mj_step(&cart.model(), d);
    REQUIRE(d->warning[mjWARN_BADQACC].number == 1);
    printed = 0;
    cart.step(x, Vector<double>::Constant(1, 1.0), next);
    CHECK(cart.take_refusals().first ==
          detail::concat("NaN, Inf or a value beyond 1e10 in qacc at DOF ",
                         d->warning[mjWARN_BADQACC].lastinfo, ", so it reset the state"));
    mj_deleteData(d);
  }
  // A result MuJoCo would refuse to step from.
  const auto coarse = mujoco_cartpole(1, 10.0);
  x = good;
  x(2) = 5e9;
  coarse.step(x, Vector<double>::Constant(1, 1.0), next);
  CHECK_THAT(coarse.take_refusals().first,
             Catch::StartsWith("the step's result qpos[0] is 500000001") &&
                 Catch::EndsWith(", beyond MuJoCo's bound of 1e+10"));
  CHECK(printed == 0);
  mju_user_warning = nullptr;
}
