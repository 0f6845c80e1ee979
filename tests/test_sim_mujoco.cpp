// Tests of the MuJoCo adapter (include/sbptt/sim/mujoco.hpp) against independent truth: our
// own cart pole (CartPoleModel::Physical) written as MJCF (tests/models/) must give the same
// trajectories (same equations, same scheme) and the same A, B as the analytic Jacobians to
// the accuracy of finite differences; MuJoCo's RK4 must converge to our Euler at first order;
// threads must not change a bit; bad models and bad states must be reported, never hidden.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "sbptt/bptt/engine.hpp"
#include "sbptt/bptt/losses.hpp"
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/core/taylor_test.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "sbptt/sim/cartpole.hpp"
#include "sbptt/sim/mujoco.hpp"

#include "mujoco_cartpole_layout.hpp"
#include "support/mujoco_models.hpp"
#include "support/taylor_remainder.hpp"

using namespace sbptt;
using sbptt::examples::to_mujoco_layout;
using sbptt::testing::model_path;
using sbptt::testing::mujoco_cartpole;
using sbptt::testing::write_temp_model;

namespace {

static_assert(static_assert_simulator<MujocoSimulator<double>>());
static_assert(static_assert_simulator<MujocoSimulator<float>>());

/// A CartPole state anywhere on the circle with brisk velocities.
Vector<double> random_cart_state(Index poles, Rng& rng) {
  Vector<double> x(2 + 2 * poles);
  for (Index i = 0; i < x.size(); ++i) x(i) = rng.uniform(-2.0, 2.0);
  for (Index i = 0; i < poles; ++i) x(2 + 2 * i) = rng.uniform(-3.2, 3.2);
  return x;
}

CartPole<double, Eigen::Dynamic> physical_cartpole(Index poles, Index steps) {
  CartPoleOptions options;
  options.model = CartPoleModel::Physical;
  options.steps = steps;  // horizon 1: dt = 1 / steps, as the MJCF's timestep below
  return CartPole<double, Eigen::Dynamic>(poles, options);
}

/// Largest |CartPole − MuJoCo| over every state of a 1-second rollout from `starts` random
/// states under a smooth force.
double trajectory_gap(const CartPole<double, Eigen::Dynamic>& cart,
                      const MujocoSimulator<double>& mj, Index poles, Index steps, int starts) {
  Rng rng(11);
  double worst = 0;
  for (int s = 0; s < starts; ++s) {
    Vector<double> xc = random_cart_state(poles, rng), xm = to_mujoco_layout(xc, poles);
    Vector<double> next_c, next_m;
    Eigen::Matrix<double, 1, 1> u_cart;
    Vector<double> u_mj(1);
    for (Index n = 0; n < steps; ++n) {
      const double t = static_cast<double>(n) / static_cast<double>(steps);
      u_cart(0) = u_mj(0) = 3.0 * std::sin(7.0 * t + s);
      cart.step(xc, u_cart, next_c);
      mj.step(xm, u_mj, next_m);
      xc = next_c;
      xm = next_m;
      worst = std::max(worst, (to_mujoco_layout(xc, poles) - xm).cwiseAbs().maxCoeff());
    }
  }
  return worst;
}

}  // namespace

TEST_CASE("mujoco: the MJCF cart pole steps exactly as CartPole's physical model",
          "[sim][mujoco]") {
  // Same Lagrangian, same semi-implicit Euler, and no constraint at all (no contact, limit or
  // equality), so MuJoCo's constraint solver is idle and qacc = M(q)⁻¹ (τ − c(q, q̇)) exactly:
  // the two differ only in the rounding of different operation orders. Measured: at most
  // 3.6e-15 over 1 s rollouts, 1 and 2 poles, dt from 1/50 to 1/800, so the gap does not shrink
  // with dt (there is no discretisation gap to shrink); 1e-12 leaves room for other libms.
  for (const int poles : {1, 2}) {
    for (const Index steps : {50, 100, 200, 400}) {
      INFO(poles << " pole(s), dt = 1/" << steps);
      const auto cart = physical_cartpole(poles, steps);
      const auto mj = mujoco_cartpole(poles, 1.0 / static_cast<double>(steps));
      REQUIRE(mj.state_dim() == cart.state_dim());
      REQUIRE(mj.control_dim() == 1);
      REQUIRE(mj.dt() == cart.dt());
      CHECK(trajectory_gap(cart, mj, poles, steps, 4) < 1e-12);
    }
  }
}

TEST_CASE("mujoco: with RK4 the MJCF cart pole converges to CartPole at first order in dt",
          "[sim][mujoco]") {
  // A real discretisation gap: MuJoCo's RK4 (error O(dt⁴)) against our semi-implicit Euler
  // (O(dt)) on the same ODE. The gap must be well above rounding and halve with dt, which
  // shows both integrate the same continuous dynamics. Measured ratios are printed on failure.
  for (const int poles : {1, 2}) {
    std::vector<double> gaps;
    for (const Index steps : {100, 200, 400, 800}) {
      gaps.push_back(trajectory_gap(physical_cartpole(poles, steps),
                                    mujoco_cartpole(poles, 1.0 / static_cast<double>(steps),
                                                    mjINT_RK4),
                                    poles, steps, 2));
    }
    INFO(poles << " pole(s): gaps " << gaps[0] << ", " << gaps[1] << ", " << gaps[2] << ", "
               << gaps[3]);
    CHECK(gaps[0] > 1e-4);
    for (std::size_t k = 1; k < gaps.size(); ++k) {
      const double ratio = gaps[k - 1] / gaps[k];
      CHECK(ratio > 1.7);
      CHECK(ratio < 2.3);
    }
  }
}

TEST_CASE("mujoco: A and B of mjd_transitionFD equal CartPole's analytic Jacobians",
          "[sim][mujoco]") {
  // Centered differences with ε = 1e-6: truncation ε² |x'''| ~ 1e-12, rounding δ/ε with
  // δ ~ 1e-16 |x'| ~ 1e-15, so about 1e-9 absolute. Measured: 6e-11 worst.
  for (const int poles : {1, 2}) {
    const auto cart = physical_cartpole(poles, 100);
    const auto mj = mujoco_cartpole(poles, 0.01);
    const Matrix<double> pi = examples::mujoco_layout_permutation(poles);
    Rng rng(5);
    for (int trial = 0; trial < 10; ++trial) {
      const Vector<double> xc = random_cart_state(poles, rng);
      Eigen::Matrix<double, 1, 1> u;
      u(0) = rng.uniform(-5.0, 5.0);
      Matrix<double> a, b_mj, a_mj;
      Vector<double> b;
      cart.jacobians(xc, u, a, b);
      mj.jacobians(to_mujoco_layout(xc, poles), Vector<double>(u), a_mj, b_mj);
      INFO(poles << " pole(s), trial " << trial);
      CHECK((pi * a * pi.transpose() - a_mj).cwiseAbs().maxCoeff() < 1e-9);
      CHECK((pi * b - b_mj).cwiseAbs().maxCoeff() < 1e-9);
      // The adapter's own twin: its A, B and VJP against central differences of its step,
      // and its VJP against the transposes of its A and B.
      const auto check = check_jacobians(mj, to_mujoco_layout(xc, poles), Vector<double>(u));
      CHECK(check.state_jacobian_error < 1e-7);
      CHECK(check.control_jacobian_error < 1e-6);
      CHECK(check.vjp_error < 1e-6);
      CHECK(vjp_jacobian_mismatch(mj, to_mujoco_layout(xc, poles), Vector<double>(u)) < 1e-14);
    }
  }
}

TEST_CASE("mujoco: A and B are the derivatives of the step with every integrator",
          "[sim][mujoco]") {
  // A cart with a double pendulum and three kinds of actuator (motor, position, velocity:
  // their forces depend on ctrl, qpos and qvel). Two truths that need only the step: sbptt's
  // own central differences of it (check_jacobians), and the Taylor remainder
  // |P(x + h v, u + h w) − P(x, u) − h (A v + B w)|, which must fall 4-fold when h halves.
  // MuJoCo 2.2's mjd_transitionFD gave B off by up to 5.2e6 (relative) with RK4: it reuses
  // the unperturbed state's position and velocity stages in RK4's later stages.
  const std::string arm =
      "<mujoco><option timestep='0.005' integrator='INTEGRATOR'><flag contact='disable'/>"
      "</option><default><joint damping='0.1'/><geom contype='0' conaffinity='0'/></default>"
      "<worldbody><body><joint name='slider' type='slide' axis='1 0 0'/>"
      "<geom type='box' size='0.2 0.1 0.05' mass='1'/><body><joint name='h1' type='hinge' "
      "axis='0 1 0'/><geom type='capsule' fromto='0 0 0 0 0 0.6' size='0.03' mass='0.3'/>"
      "<body pos='0 0 0.6'><joint name='h2' type='hinge' axis='0 1 0'/><geom type='capsule' "
      "fromto='0 0 0 0 0 0.5' size='0.03' mass='0.2'/></body></body></body></worldbody>"
      "<actuator><motor joint='slider' gear='5'/><position joint='h1' kp='20'/>"
      "<velocity joint='h2' kv='2'/></actuator></mujoco>";
  for (const std::string integrator : {"Euler", "implicit", "RK4"}) {
    std::string text = arm;
    text.replace(text.find("INTEGRATOR"), 10, integrator);
    const MujocoModelPtr model = load_mujoco_model(write_temp_model("arm.xml", text));
    const MujocoSimulator<double> sim(*model);
    Rng rng(21);
    for (int trial = 0; trial < 5; ++trial) {
      Vector<double> x(6), u(3), v(6), w(3);
      for (auto* vector : {&x, &u, &v, &w})
        for (Index i = 0; i < vector->size(); ++i) (*vector)(i) = rng.uniform(-1.0, 1.0);
      const auto check = check_jacobians(sim, x, u);
      std::vector<double> remainders;
      for (const double h : {4e-2, 2e-2, 1e-2})
        remainders.push_back(testing::taylor_remainder(sim, x, u, v, w, h));
      INFO(integrator << ", trial " << trial << ": A " << check.state_jacobian_error << ", B "
                      << check.control_jacobian_error << ", VJP " << check.vjp_error
                      << "; remainders " << remainders[0] << ", " << remainders[1] << ", "
                      << remainders[2]);
      CHECK(check.state_jacobian_error < 1e-6);
      CHECK(check.control_jacobian_error < 1e-6);
      CHECK(check.vjp_error < 1e-6);
      // The library's Taylor test sees the differences' own error (order 1 in B where the step
      // is linear in u), and bounds it well below 1e-8.
      const auto taylor = taylor_test(sim, x, u, static_cast<std::uint64_t>(trial + 1));
      INFO(describe(taylor));
      CHECK(taylor.passed(1e-8));
      for (std::size_t k = 1; k < remainders.size(); ++k) {
        CHECK(remainders[k - 1] / remainders[k] > 3.5);
        CHECK(remainders[k - 1] / remainders[k] < 4.5);
      }
    }
  }
}

TEST_CASE("mujoco: the finite-difference step is an option and matters as theory says",
          "[sim][mujoco]") {
  // ε = 1e-2 leaves a truncation error ε² |x'''|/6 far above ε = 1e-6's; both stay close.
  const auto cart = physical_cartpole(1, 100);
  const MujocoModelPtr model = load_mujoco_model(model_path(1));
  const MujocoSimulator<double> coarse(*model, MujocoOptions{1e-2});
  const MujocoSimulator<double> fine(*model);
  CHECK(fine.options().fd_step == 1e-6);
  const Vector<double> xc = (Vector<double>(4) << 0.3, -1.0, 2.5, 1.5).finished();
  Eigen::Matrix<double, 1, 1> u;
  u(0) = 1.0;
  Matrix<double> a, a_coarse, a_fine, b_coarse, b_fine;
  Vector<double> b;
  cart.jacobians(xc, u, a, b);
  const Matrix<double> pi = examples::mujoco_layout_permutation(1);
  coarse.jacobians(to_mujoco_layout(xc, 1), Vector<double>(u), a_coarse, b_coarse);
  fine.jacobians(to_mujoco_layout(xc, 1), Vector<double>(u), a_fine, b_fine);
  const double error_coarse = (pi * a * pi.transpose() - a_coarse).cwiseAbs().maxCoeff();
  const double error_fine = (pi * a * pi.transpose() - a_fine).cwiseAbs().maxCoeff();
  INFO("coarse " << error_coarse << ", fine " << error_fine);
  CHECK(error_coarse > 100 * error_fine);
  CHECK(error_coarse < 1e-4);
  CHECK_THROWS_WITH(MujocoSimulator<double>(*model, MujocoOptions{0.0}),
                    Catch::Contains("fd_step = 0"));
  // A step of 2e10 took probes past MuJoCo's bound of 1e10, which reset the mjData and so
  // printed its warning to stdout and MUJOCO_LOG.TXT; a step past 1 is no derivative anyway.
  CHECK_THROWS_WITH(MujocoSimulator<double>(*model, MujocoOptions{2e10}),
                    Catch::Contains("fd_step = 20000000000, expected a finite ε in (0, 1]"));
  CHECK_NOTHROW(MujocoSimulator<double>(*model, MujocoOptions{1.0}));
}

TEST_CASE("mujoco: threads never share an mjData and never change a bit", "[sim][mujoco]") {
  const auto mj = mujoco_cartpole(2, 0.01);
  Rng rng(3);
  constexpr int kCalls = 200;
  std::vector<Vector<double>> states, controls;
  for (int i = 0; i < kCalls; ++i) {
    states.push_back(to_mujoco_layout(random_cart_state(2, rng), 2));
    controls.push_back(Vector<double>::Constant(1, rng.uniform(-5.0, 5.0)));
  }
  struct Result {
    Vector<double> next, lambda_x, lambda_u;
    Matrix<double> a, b;
  };
  // Step and Jacobians by `stepper`, the VJP always by `mj`.
  auto compute_with = [&](const MujocoSimulator<double>& stepper, int i, Result& r) {
    const auto n = static_cast<std::size_t>(i), after = static_cast<std::size_t>((i + 1) % kCalls);
    stepper.step(states[n], controls[n], r.next);
    stepper.jacobians(states[n], controls[n], r.a, r.b);
    mj.vjp(states[n], controls[n], states[after], &r.lambda_x, &r.lambda_u);
  };
  std::vector<Result> serial(kCalls), parallel(kCalls);
  for (int i = 0; i < kCalls; ++i) compute_with(mj, i, serial[static_cast<std::size_t>(i)]);
  // Three threads interleave calls in different orders over one shared simulator (and a copy,
  // which shares the pool), so the mjData that serves a call has served other states before.
  const MujocoSimulator<double> copy = mj;  // NOLINT(performance-unnecessary-copy-initialization)
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t) {
    threads.emplace_back([&, t] {
      for (int k = 0; k < kCalls; ++k) {
        const int i = (t == 1) ? kCalls - 1 - k : (k * 7 + t) % kCalls;
        if (i % 3 != t) continue;
        compute_with(t == 2 ? copy : mj, i, parallel[static_cast<std::size_t>(i)]);
      }
    });
  }
  for (auto& thread : threads) thread.join();
  for (int i = 0; i < kCalls; ++i) {
    const auto& s = serial[static_cast<std::size_t>(i)];
    const auto& p = parallel[static_cast<std::size_t>(i)];
    INFO("call " << i);
    CHECK(p.next == s.next);
    CHECK(p.a == s.a);
    CHECK(p.b == s.b);
    CHECK(p.lambda_x == s.lambda_x);
    CHECK(p.lambda_u == s.lambda_u);
  }
}

TEST_CASE("mujoco: the engine's gradients are bitwise equal for 1, 2 and 3 threads",
          "[sim][mujoco][bptt]") {
  const auto mj = mujoco_cartpole(2, 0.01);
  auto net = Network<double>::mlp(mj.state_dim(), {16}, mj.control_dim());
  Rng rng(9);
  glorot_uniform(net, rng);
  Matrix<double> x0(mj.state_dim(), 7);
  for (Index j = 0; j < x0.cols(); ++j)
    x0.col(j) = to_mujoco_layout(random_cart_state(2, rng), 2);
  using Loss = SquaredDistanceLoss<Vector<double>>;
  const Objective<Loss> objective{Loss{Vector<double>::Zero(mj.state_dim())}};
  std::vector<GradientPair<double>> pairs;
  for (const Index threads : {1, 2, 3}) {
    Engine engine(mj, net, objective, 25);
    engine.set_threads(threads, 0);  // split every per-sample loop
    GradientPair<double> pair;
    engine.regular_and_modified(x0, pair);
    pairs.push_back(pair);
  }
  REQUIRE(std::isfinite(pairs[0].loss));
  REQUIRE(pairs[0].regular.norm() > 0);
  for (std::size_t t = 1; t < pairs.size(); ++t) {
    CHECK(pairs[t].loss == pairs[0].loss);
    CHECK(pairs[t].regular == pairs[0].regular);
    CHECK(pairs[t].modified == pairs[0].modified);
  }
}

TEST_CASE("mujoco: float states step as double ones rounded", "[sim][mujoco]") {
  const MujocoModelPtr model = load_mujoco_model(model_path(2));
  const MujocoSimulator<double> sim_d(*model);
  const MujocoSimulator<float> sim_f(*model);
  Rng rng(4);
  const Vector<double> x = to_mujoco_layout(random_cart_state(2, rng), 2);
  const Vector<double> u = Vector<double>::Constant(1, 0.75);  // exact in float
  Vector<double> next_d;
  Vector<float> next_f;
  sim_d.step(x.cast<float>().cast<double>(), u, next_d);
  sim_f.step(x.cast<float>(), u.cast<float>(), next_f);
  CHECK((next_f.cast<double>() - next_d).cwiseAbs().maxCoeff() < 1e-6);
  Matrix<double> a_d, b_d;
  Matrix<float> a_f, b_f;
  sim_d.jacobians(x.cast<float>().cast<double>(), u, a_d, b_d);
  sim_f.jacobians(x.cast<float>(), u.cast<float>(), a_f, b_f);
  CHECK(a_f == a_d.cast<float>());
  CHECK(b_f == b_d.cast<float>());
  CHECK(sim_f.dt() == 0.01f);
}

TEST_CASE("mujoco: a state MuJoCo would reset gives NaN, not a silently reset state",
          "[sim][mujoco]") {
  // MuJoCo's warnings go through this process-wide hook (by default: stdout and a
  // MUJOCO_LOG.TXT in the working directory); the adapter must not trigger it.
  static int printed = 0;
  mju_user_warning = [](const char*) { ++printed; };
  const auto mj = mujoco_cartpole(1, 0.01);
  const Vector<double> good = (Vector<double>(4) << 0.1, 3.0, 0.2, -0.5).finished();
  const Vector<double> u = Vector<double>::Constant(1, 1.0);
  Vector<double> before, after, next;
  mj.step(good, u, before);
  for (const double bad : {std::nan(""), 1e11, -std::numeric_limits<double>::infinity()}) {
    INFO("bad value " << bad);
    Vector<double> x = good;
    x(1) = bad;
    mj.step(x, u, next);
    CHECK(next.array().isNaN().all());
    Matrix<double> a, b;
    mj.jacobians(good, Vector<double>::Constant(1, bad), a, b);
    CHECK(a.array().isNaN().all());
    CHECK(b.array().isNaN().all());
  }
  // An acceleration beyond 1e10 (MuJoCo's mjMAXVAL) from an acceptable state: the pole's
  // centripetal pull m l θ̇² = 5e10 at θ̇ = 1e6. MuJoCo resets to qpos0 and records a warning;
  // the adapter reports NaN instead of the reset state.
  Vector<double> spinning = good;
  spinning(3) = 1e6;
  mj.step(spinning, u, next);
  CHECK(next.array().isNaN().all());
  Matrix<double> a, b;
  mj.jacobians(spinning, u, a, b);
  CHECK(a.array().isNaN().all());
  mj.step(good, u, after);  // the pooled mjData carries nothing over
  CHECK(after == before);
  // A step that MuJoCo takes but whose result it would refuse as the next step's state: the
  // cart at 5e9 m/s for 10 s ends 5e10 m away. Found by a fault probe: as the last step of a
  // rollout it was never refused (`mujoco --dt 1e6 --steps 1`: a final test loss of 6.9e19).
  const auto coarse = mujoco_cartpole(1, 10.0);
  Vector<double> fast = good;
  fast(2) = 5e9;
  Vector<double> accepted = fast;
  accepted(2) = 1e8;  // ends 1e9 m away: within 1e10
  coarse.step(accepted, u, next);
  CHECK(next.allFinite());
  CHECK(std::abs(next(0)) > 1e9);
  coarse.step(fast, u, next);
  CHECK(next.array().isNaN().all());
  CHECK(printed == 0);
  mju_user_warning = nullptr;
}

TEST_CASE("mujoco: models that cannot be used are refused with a reason", "[sim][mujoco]") {
  // A file it cannot read, with the system's reason (MuJoCo says "not found" for any).
  CHECK_THROWS_AS(load_mujoco_model("/nonexistent/scene.xml"), IoError);
  CHECK_THROWS_WITH(load_mujoco_model("/nonexistent/scene.xml"),
                    Catch::Contains("cannot open '/nonexistent/scene.xml' for reading (No such "
                                    "file or directory)"));
  CHECK_THROWS_WITH(load_mujoco_model(std::filesystem::temp_directory_path().string()),
                    Catch::Contains("is a directory; expected an MJCF or URDF file"));
  // MuJoCo's own parser message is quoted.
  const std::string broken = write_temp_model("broken.xml", "<mujoco><worldbody><body>");
  CHECK_THROWS_WITH(load_mujoco_model(broken),
                    Catch::Contains(broken) && Catch::Contains("XML parse error"));
  struct Refused {
    std::string name, text, reason;
  };
  // MuJoCo loads a NaN with a warning and steps it into NaN states from the first step.
  for (const Refused& r :
       {Refused{"free.xml",
                "<mujoco><worldbody><body><freejoint name='f'/><geom size='0.1'/></body>"
                "</worldbody><actuator><general joint='f' gear='1 0 0 0 0 0'/></actuator></mujoco>",
                "nq = 7 position coordinates but nv = 6"},
        Refused{"ball.xml",
                "<mujoco><worldbody><body><joint name='j' type='ball'/><geom size='0.1'/></body>"
                "</worldbody><actuator><general joint='j' gear='1 0 0 0 0 0'/></actuator></mujoco>",
                "nq = 4 position coordinates but nv = 3 velocity coordinates (a free or ball "
                "joint: its orientation is a quaternion"},
        Refused{"passive.xml",
                "<mujoco><worldbody><body><joint type='hinge'/><geom size='0.1'/></body>"
                "</worldbody></mujoco>",
                "no actuator (nu = 0)"},
        Refused{"jointless.xml",
                "<mujoco><worldbody><body><geom size='0.1'/><site name='s'/></body></worldbody>"
                "<actuator><motor site='s' gear='1 0 0 0 0 0'/></actuator></mujoco>",
                "no joint (nv = 0) and no actuator activation (na = 0), so its state is empty"},
        Refused{"nan_damping.xml",
                "<mujoco><worldbody><body><joint name='j' type='hinge' damping='nan'/><geom "
                "size='0.1'/></body></worldbody><actuator><motor joint='j'/></actuator></mujoco>",
                "the model's dof_damping[0] is nan; expected finite"}}) {
    const std::string file = write_temp_model(r.name, r.text);
    const MujocoModelPtr model = load_mujoco_model(file);
    CHECK_THROWS_WITH(MujocoSimulator<double>(*model), Catch::Contains(r.reason));
    std::filesystem::remove(file);
  }
  const MujocoModelPtr edited = load_mujoco_model(model_path(1));
  edited->opt.gravity[1] = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(MujocoSimulator<double>(*edited), Catch::Contains("opt.gravity[1] is inf"));
  edited->opt.gravity[1] = 0;
  edited->body_mass[2] = -std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH(MujocoSimulator<double>(*edited), Catch::Contains("body_mass[2] is -inf"));
  std::filesystem::remove(broken);
}

namespace {
std::vector<std::string> hooked;
void hook(const char* message) { hooked.emplace_back(message); }
}  // namespace

TEST_CASE("mujoco: the loader's warnings are collected when asked, else left to the hook",
          "[sim][mujoco]") {
  const std::string file = write_temp_model(
      "nan_gravity.xml", "<mujoco><option gravity='0 0 nan'/><worldbody><body><joint name='j' "
                         "type='hinge'/><geom size='0.1'/></body></worldbody><actuator><motor "
                         "joint='j'/></actuator></mujoco>");
  const std::string expected = "XML contains a 'NaN'. Please check it carefully.";
  hooked.clear();
  mju_user_warning = hook;
  std::vector<std::string> warnings;
  (void)load_mujoco_model(file, &warnings);
  CHECK(warnings == std::vector<std::string>{expected});
  CHECK(hooked.empty());
  CHECK(mju_user_warning == &hook);  // the user's hook is back
  (void)load_mujoco_model(file);
  CHECK(hooked == std::vector<std::string>{expected});
  mju_user_warning = nullptr;
  std::filesystem::remove(file);
}

TEST_CASE("mujoco: the simulator owns a copy of the model; sizes are checked",
          "[sim][mujoco]") {
  const MujocoModelPtr model = load_mujoco_model(model_path(1));
  const MujocoSimulator<double> mj(*model);
  model->opt.timestep = 0.5;  // later edits do not reach the simulator
  CHECK(mj.dt() == 0.01);
  CHECK(mj.model().opt.timestep == 0.01);
  const Vector<double> rest = mj.initial_state();
  CHECK(rest == Vector<double>::Zero(4));  // qpos0: cart at 0, pole upright
  Vector<double> next;
  CHECK_THROWS_WITH(mj.step(Vector<double>::Zero(3), Vector<double>::Zero(1), next),
                    Catch::Contains("x has size 3, expected state_dim() = 2 nv + na = 4"));
  CHECK_THROWS_WITH(mj.step(Vector<double>::Zero(4), Vector<double>::Zero(2), next),
                    Catch::Contains("u has size 2, expected control_dim() = nu = 1"));
}
