// Schrodinger1D (paper §6): derivatives against finite differences and Taylor remainders, the
// step against a dense pivoted solve, the paper's sanity values, and unitarity.
#include <catch2/catch.hpp>

// Eigen's checks stay on in Release here, and throw, so that the no-heap test below can fail.
#include <stdexcept>
#define EIGEN_RUNTIME_NO_MALLOC
#define eigen_assert(x) \
  do {                  \
    if (!(x)) throw std::logic_error("Eigen assertion failed: " #x); \
  } while (false)

#include <Eigen/LU>
#include <cmath>
#include <complex>
#include <numbers>
#include <thread>
#include <vector>

#include "sbptt/objectives/quantum.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/sim/schrodinger.hpp"

namespace {

using sbptt::Index;
using Sim = sbptt::Schrodinger1D<double, 32>;
using State = Sim::State;
using Control = Sim::Control;
using CMatrix = Eigen::MatrixXcd;
using CVector = Eigen::VectorXcd;

template <class S>
typename S::State random_state(const S& sim, sbptt::Rng& rng) {
  typename S::State x(sim.state_dim());
  for (Index i = 0; i < x.size(); ++i) x(i) = static_cast<typename S::Scalar>(rng.normal());
  x /= x.norm();
  return x;
}

Control control(double u) {
  Control c;
  c << u;
  return c;
}

// H(u) assembled densely from the stated formula: the independent reference.
template <class S>
Eigen::MatrixXd dense_hamiltonian(const S& sim, double u) {
  const Index n = sim.grid_size();
  const double dx = static_cast<double>(sim.length()) / static_cast<double>(n + 1);
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(n, n);
  for (Index j = 0; j < n; ++j) {
    h(j, j) = 2.0 / (dx * dx) + u * static_cast<double>(j + 1) * dx;
    if (j > 0) h(j, j - 1) = -1.0 / (dx * dx);
    if (j + 1 < n) h(j, j + 1) = -1.0 / (dx * dx);
  }
  return h;
}

CVector to_complex(const Eigen::VectorXd& x) {
  CVector z(x.size() / 2);
  for (Index j = 0; j < z.size(); ++j) z(j) = {x(2 * j), x(2 * j + 1)};
  return z;
}

double summed_loss(const Sim& sim, State psi, double u,
                   const sbptt::Objective<sbptt::QuantumInfidelityLoss<double, 32>>& objective) {
  double total = 0;
  State next;
  for (Index n = 1; n <= sim.steps(); ++n) {
    sim.step(psi, control(u), next);
    psi = next;
    total += objective.step_weight * objective.state_loss(psi, nullptr);
  }
  return total;
}

}  // namespace

TEST_CASE("schrodinger: satisfies the Simulator concept with the paper's defaults",
          "[sim][quantum]") {
  STATIC_REQUIRE(sbptt::static_assert_simulator<Sim>());
  STATIC_REQUIRE(sbptt::static_assert_simulator<sbptt::Schrodinger1D<float, 8>>());
  const Sim sim;
  CHECK(sim.state_dim() == 64);
  CHECK(sim.control_dim() == 1);
  CHECK(sim.dt() == 0.0625);
  CHECK(sim.steps() == 128);
  CHECK(sim.horizon() == 8.0);
  CHECK(sim.dx() == Approx(2.0 / 33.0).epsilon(1e-15));
  CHECK(sim.grid()(31) == Approx(64.0 / 33.0).epsilon(1e-15));
}

TEST_CASE("schrodinger: the step equals a dense pivoted Crank-Nicolson solve", "[sim][quantum]") {
  const Sim sim;
  sbptt::Rng rng(11);
  for (int trial = 0; trial < 10; ++trial) {
    const State x = random_state(sim, rng);
    const double u = rng.uniform(-10.0, 10.0);
    const CMatrix ihh = std::complex<double>(0, 0.5 * sim.dt()) * dense_hamiltonian(sim, u);
    const CMatrix eye = CMatrix::Identity(32, 32);
    const CVector expected = (eye + ihh).partialPivLu().solve((eye - ihh) * to_complex(x));
    State next;
    sim.step(x, control(u), next);
    CHECK((to_complex(next) - expected).cwiseAbs().maxCoeff() < 1e-13);
  }
}

TEST_CASE("tridiagonal: solve and adjoint solve match a dense pivoted LU", "[sim][quantum]") {
  sbptt::Rng rng(17);
  const Index n = 9;
  auto draw = [&] { return std::complex<double>(rng.normal(), rng.normal()); };
  CVector diag(n), rhs(n);
  for (Index j = 0; j < n; ++j) {
    diag(j) = 6.0 + draw();
    rhs(j) = draw();
  }
  const std::complex<double> lower = draw(), upper = draw();  // unequal: a general matrix
  CMatrix dense = diag.asDiagonal();
  for (Index j = 0; j + 1 < n; ++j) {
    dense(j + 1, j) = lower;
    dense(j, j + 1) = upper;
  }
  const sbptt::ConstantTridiagonalLu<std::complex<double>> lu(diag, lower, upper);
  CVector x = rhs, y = rhs;
  lu.solve_in_place(x);
  lu.adjoint_solve_in_place(y);
  CHECK((x - dense.partialPivLu().solve(rhs)).norm() < 1e-13);
  CHECK((y - dense.adjoint().partialPivLu().solve(rhs)).norm() < 1e-13);
  CHECK_THROWS_AS(sbptt::ConstantTridiagonalLu<double>(Eigen::VectorXd::Zero(3), 1.0, 1.0),
                  sbptt::InvalidArgument);
}

TEST_CASE("schrodinger: jacobians and vjp match finite differences at random points",
          "[sim][quantum]") {
  sbptt::Rng rng(2024);
  auto check_all = [&](const auto& sim, int pairs) {
    for (int trial = 0; trial < pairs; ++trial) {
      const auto x = random_state(sim, rng);
      const Control u = control(rng.uniform(-10.0, 10.0));
      const auto check = sbptt::check_jacobians(sim, x, u);
      INFO("Nx = " << sim.grid_size() << ", u = " << u(0));
      CHECK(check.state_jacobian_error <= 1e-6);
      CHECK(check.control_jacobian_error <= 1e-6);
      CHECK(check.vjp_error <= 1e-6);
      CHECK(sbptt::vjp_jacobian_mismatch(sim, x, u) <= 1e-12);
    }
  };
  SECTION("Nx = 32") { check_all(Sim(), 24); }
  SECTION("Nx = 8") { check_all(sbptt::Schrodinger1D<double, 8>(), 20); }
  SECTION("Nx = 1 (no off-diagonals)") { check_all(sbptt::Schrodinger1D<double, 1>(), 5); }
  SECTION("Dynamic Nx = 13, other options") {
    check_all(sbptt::Schrodinger1D<double, Eigen::Dynamic>(13, {0.01, 50, 1.5}), 20);
  }
}

TEST_CASE("schrodinger: Taylor remainder of the step is second order", "[sim][quantum]") {
  const Sim sim;
  sbptt::Rng rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const State x = random_state(sim, rng);
    const State dx = random_state(sim, rng);
    const double u = rng.uniform(-10.0, 10.0), du = rng.uniform(-3.0, 3.0);
    Sim::StateJacobian a;
    Sim::ControlJacobian b;
    sim.jacobians(x, control(u), a, b);
    State base;
    sim.step(x, control(u), base);
    const State linear = a * dx + b * du;
    auto remainder = [&](double t) {
      State moved;
      sim.step(x + t * dx, control(u + t * du), moved);
      return (moved - base - t * linear).norm();
    };
    for (const double t : {1e-2, 1e-3}) {
      const double ratio = remainder(t) / remainder(t / 2);
      INFO("t = " << t << ", ratio = " << ratio);
      CHECK(ratio >= 3.5);
      CHECK(ratio <= 4.5);
    }
  }
}

TEST_CASE("schrodinger: adjoint gradient of a rollout loss matches finite differences",
          "[sim][quantum]") {
  const Sim sim;
  // Target 2 overlaps the start strongly, so the gradient is well above FD round-off.
  const auto objective = sbptt::quantum_objective(sim, 2);
  sbptt::Rng rng(5);
  const State x0 = sim.initial_states(rng, 1).col(0);
  const Index m = 12;
  Eigen::VectorXd controls(m);
  for (Index n = 0; n < m; ++n) controls(n) = rng.uniform(-5.0, 5.0);

  auto loss_of = [&](const Eigen::VectorXd& c, std::vector<State>* states) {
    State x = x0, next;
    double total = 0;
    if (states) states->assign(1, x0);
    for (Index n = 0; n < m; ++n) {
      sim.step(x, control(c(n)), next);
      x = next;
      total += objective.state_loss(x, nullptr);
      if (states) states->push_back(x);
    }
    return total;
  };
  std::vector<State> xs;
  loss_of(controls, &xs);
  Eigen::VectorXd grad(m);
  State lambda, seed, lambda_x;
  Control lambda_u;
  objective.state_loss(xs[static_cast<std::size_t>(m)], &lambda);
  for (Index n = m - 1; n >= 0; --n) {
    const auto i = static_cast<std::size_t>(n);
    sim.vjp(xs[i], control(controls(n)), lambda, &lambda_x, &lambda_u);
    grad(n) = lambda_u(0);
    objective.state_loss(xs[i], &seed);
    lambda = lambda_x + seed;
  }
  auto f = [&](const Eigen::VectorXd& c, Eigen::VectorXd& out) {
    out.resize(1);
    out(0) = loss_of(c, nullptr);
  };
  const Eigen::MatrixXd fd = sbptt::finite_difference_jacobian<double>(f, controls, 1);
  INFO("adjoint " << grad.transpose() << "\nfd      " << fd);
  CHECK(sbptt::relative_error<double>(grad.transpose(), fd) < 1e-7);
}

TEST_CASE("schrodinger: eigenstates and energies of H(0)", "[sim][quantum]") {
  const Sim sim;
  const double expected[] = {2.4655, 9.8398, 22.0561, 39.0037, 60.5291};
  const Eigen::MatrixXd h = dense_hamiltonian(sim, 0.0);
  for (Index n = 1; n <= 32; ++n) {
    const State phi = sim.eigenstate(n);
    const double energy = sim.eigen_energy(n);
    Eigen::VectorXd re(32);
    for (Index j = 0; j < 32; ++j) {
      re(j) = phi(2 * j);
      CHECK(phi(2 * j + 1) == 0.0);
    }
    INFO("n = " << n);
    CHECK(std::abs(phi.squaredNorm() - 1.0) < 1e-14);
    CHECK((h * re - energy * re).cwiseAbs().maxCoeff() <= 1e-12 * std::max(1.0, energy / 100));
    if (n <= 5) CHECK(std::abs(energy - expected[n - 1]) < 1e-4);
  }
  CHECK(sim.eigenstate(1)(0) > 0);  // ground state has no node
  CHECK_THROWS_AS(sim.eigenstate(0), sbptt::InvalidArgument);
  CHECK_THROWS_AS(sim.eigenstate(33), sbptt::InvalidArgument);
  CHECK_THROWS_AS(sim.eigen_energy(0), sbptt::InvalidArgument);
}

TEST_CASE("schrodinger: fidelity gradient matches finite differences", "[sim][quantum]") {
  const Sim sim;
  sbptt::Rng rng(3);
  const State phi = random_state(sim, rng), psi = random_state(sim, rng);
  State grad;
  const double f = sim.fidelity(phi, psi, &grad);
  const std::complex<double> z = to_complex(phi).dot(to_complex(psi));  // conj(φ)·ψ
  CHECK(f == Approx(std::norm(z)).epsilon(1e-14));
  auto fn = [&](const Eigen::VectorXd& p, Eigen::VectorXd& out) {
    out.resize(1);
    out(0) = sim.fidelity(phi, p);
  };
  const Eigen::MatrixXd fd = sbptt::finite_difference_jacobian<double>(fn, psi, 1);
  CHECK(sbptt::relative_error<double>(grad.transpose(), fd) < 1e-8);

  const sbptt::QuantumInfidelityLoss<double, 32> loss(sim, 4);
  State loss_grad;
  CHECK(loss(psi, &loss_grad) == Approx(1 - sim.fidelity(sim.eigenstate(4), psi)));
  State fid_grad;
  (void)sim.fidelity(sim.eigenstate(4), psi, &fid_grad);
  CHECK((loss_grad + fid_grad).norm() == 0.0);
  CHECK(loss.target_index() == 4);
}

TEST_CASE("schrodinger: paper §6 sanity values", "[sim][quantum]") {
  const Sim sim;
  const double s = 1 / std::sqrt(2.0);
  const State equal = s * (sim.eigenstate(1) + sim.eigenstate(2));

  SECTION("zero control keeps span{φ1, φ2} orthogonal to every target: loss 128") {
    sbptt::Rng rng(42);
    const Eigen::MatrixXd random = sim.initial_states(rng, 4);
    for (const Index target : {3, 4, 5}) {
      const auto objective = sbptt::quantum_objective(target);
      CHECK(objective.timing == sbptt::LossTiming::Continuous);
      CHECK(objective.step_weight == 1.0);
      CHECK(objective.control_weight == 0.0);
      // The overlaps are round-off (≲ 1e-15), so each 1 − |⟨φ, ψ⟩|² rounds to 1 exactly.
      CHECK(summed_loss(sim, equal, 0.0, objective) == 128.0);
      for (Index b = 0; b < random.cols(); ++b)
        CHECK(summed_loss(sim, random.col(b), 0.0, objective) == 128.0);
    }
  }
  SECTION("constant control table") {
    struct Row {
      Index target;
      double c1, c5;
    };
    const Row table[] = {{3, 127.8799691897, 125.8199041459},
                         {4, 127.9998969635, 127.9754968337},
                         {5, 127.9999368475, 127.9985767856}};
    for (const Row& row : table) {
      const auto objective = sbptt::quantum_objective(sim, row.target);
      INFO("TS = " << row.target);
      CHECK(std::abs(summed_loss(sim, equal, 1.0, objective) - row.c1) < 1e-9);
      CHECK(std::abs(summed_loss(sim, equal, 5.0, objective) - row.c5) < 1e-9);
    }
  }
}

TEST_CASE("schrodinger: initial states are unit superpositions of φ1 and φ2", "[sim][quantum]") {
  const Sim sim;
  sbptt::Rng rng(42), same(42);
  const Eigen::MatrixXd states = sim.initial_states(rng, 2000);
  CHECK(states == sim.initial_states(same, 2000));
  const State phi1 = sim.eigenstate(1), phi2 = sim.eigenstate(2);
  double ground_share = 0, cos_phase = 0;
  for (Index b = 0; b < states.cols(); ++b) {
    const State psi = states.col(b);
    REQUIRE(std::abs(psi.squaredNorm() - 1) < 1e-14);
    const double f1 = sim.fidelity(phi1, psi), f2 = sim.fidelity(phi2, psi);
    REQUIRE(std::abs(f1 + f2 - 1) < 1e-13);
    ground_share += f1;
    const auto z1 = to_complex(phi1).dot(to_complex(psi));
    const auto z2 = to_complex(phi2).dot(to_complex(psi));
    cos_phase += std::cos(std::arg(z1) - std::arg(z2));
  }
  // |a1|²/(|a1|²+|a2|²) ~ U[0,1] and a uniform relative phase: loose statistical bounds.
  CHECK(std::abs(ground_share / 2000 - 0.5) < 0.03);
  CHECK(std::abs(cos_phase / 2000) < 0.06);
  sbptt::Rng weighted(42);
  const Eigen::MatrixXd heavy = sim.initial_states(weighted, 2000, 3.0);
  double heavy_share = 0;
  for (Index b = 0; b < heavy.cols(); ++b) heavy_share += sim.fidelity(phi1, heavy.col(b));
  CHECK(heavy_share / 2000 > 0.75);
  CHECK_THROWS_AS(sim.initial_states(rng, -1), sbptt::InvalidArgument);
  CHECK_THROWS_AS(sim.initial_states(rng, 1, 0.0), sbptt::InvalidArgument);
}

TEST_CASE("schrodinger: unitarity invariants", "[sim][quantum]") {
  const Sim sim;
  sbptt::Rng rng(99);
  SECTION("the norm stays 1 over 1e5 random-control steps") {
    State x = random_state(sim, rng), next;
    double worst = 0;
    for (int n = 0; n < 100000; ++n) {
      sim.step(x, control(rng.uniform(-10.0, 10.0)), next);
      x = next;
      worst = std::max(worst, std::abs(x.norm() - 1));
    }
    CHECK(worst < 1e-10);
  }
  SECTION("an eigenstate under zero control only picks up a phase") {
    for (const Index n : {1, 2, 5}) {
      const State phi = sim.eigenstate(n);
      State x = phi, next;
      for (int k = 0; k < 128; ++k) {
        sim.step(x, control(0.0), next);
        x = next;
        REQUIRE(std::abs(sim.fidelity(phi, x) - 1) < 1e-12);
      }
      // the phase is the Cayley one: (1 − ihE)/(1 + ihE) per step
      const std::complex<double> ihe(0, 0.5 * sim.dt() * sim.eigen_energy(n));
      const std::complex<double> expected = std::pow((1.0 - ihe) / (1.0 + ihe), 128);
      CHECK(std::abs(to_complex(phi).dot(to_complex(x)) - expected) < 1e-11);
    }
  }
  SECTION("A is orthogonal at any control") {
    for (const double u : {-10.0, 0.0, 3.7, 10.0}) {
      Sim::StateJacobian a;
      Sim::ControlJacobian b;
      sim.jacobians(random_state(sim, rng), control(u), a, b);
      CHECK((a.transpose() * a - Eigen::MatrixXd::Identity(64, 64)).cwiseAbs().maxCoeff() <
            1e-12);
    }
  }
}

TEST_CASE("schrodinger: float matches double", "[sim][quantum][float]") {
  const Sim sim;
  const sbptt::Schrodinger1D<float, 32> simf;
  sbptt::Rng rng(8);
  State x = sim.initial_states(rng, 1).col(0), next;
  sbptt::Schrodinger1D<float, 32>::State xf = x.cast<float>(), nextf;
  double worst = 0;
  for (int n = 0; n < 128; ++n) {
    const double u = rng.uniform(-10.0, 10.0);
    sim.step(x, control(u), next);
    x = next;
    sbptt::Schrodinger1D<float, 32>::Control uf;
    uf << static_cast<float>(u);
    simf.step(xf, uf, nextf);
    xf = nextf;
    worst = std::max(worst, (xf.cast<double>() - x).cwiseAbs().maxCoeff());
  }
  CHECK(worst < 1e-4);

  Sim::StateJacobian a;
  Sim::ControlJacobian b;
  sim.jacobians(x, control(2.5), a, b);
  sbptt::Schrodinger1D<float, 32>::StateJacobian af;
  sbptt::Schrodinger1D<float, 32>::ControlJacobian bf;
  sbptt::Schrodinger1D<float, 32>::Control uf;
  uf << 2.5f;
  simf.jacobians(x.cast<float>(), uf, af, bf);
  CHECK((af.cast<double>() - a).cwiseAbs().maxCoeff() < 1e-5);
  CHECK((bf.cast<double>() - b).cwiseAbs().maxCoeff() < 1e-5);
  CHECK(sbptt::vjp_jacobian_mismatch(simf, Eigen::Matrix<float, 64, 1>(x.cast<float>()), uf) < 1e-5f);
}

TEST_CASE("schrodinger: one const instance stepped from two threads", "[sim][quantum]") {
  const Sim sim;
  auto run = [&sim](std::uint64_t seed, State& out) {
    sbptt::Rng rng(seed);
    State x = random_state(sim, rng), next, lx;
    Control lu;
    for (int n = 0; n < 2000; ++n) {
      const Control u = control(rng.uniform(-10.0, 10.0));
      sim.step(x, u, next);
      sim.vjp(x, u, next, &lx, &lu);
      x = next + 1e-3 * lx;
      x /= x.norm();
    }
    out = x;
  };
  State serial1, serial2, threaded1, threaded2;
  run(1, serial1);
  run(2, serial2);
  std::thread t1(run, 1, std::ref(threaded1));
  std::thread t2(run, 2, std::ref(threaded2));
  t1.join();
  t2.join();
  CHECK(threaded1 == serial1);
  CHECK(threaded2 == serial2);
}

TEST_CASE("schrodinger: step and vjp do not touch the heap for a fixed Nx", "[sim][quantum]") {
  const Sim sim;
  sbptt::Rng rng(4);
  const State x = random_state(sim, rng), lambda = random_state(sim, rng);
  State next, lambda_x;
  Control lambda_u;
  Sim::StateJacobian a(64, 64);
  Sim::ControlJacobian b;
  const Control u = control(1.5);
  Eigen::internal::set_is_malloc_allowed(false);
  CHECK_NOTHROW(sim.step(x, u, next));
  CHECK_NOTHROW(sim.vjp(x, u, lambda, &lambda_x, &lambda_u));
  CHECK_NOTHROW(sim.jacobians(x, u, a, b));  // A pre-sized: nothing else is allocated
  // The probe can fail: a Dynamic grid does allocate its work vectors.
  using Dyn = sbptt::Schrodinger1D<double, Eigen::Dynamic>;
  const Dyn dyn(32);
  Eigen::internal::set_is_malloc_allowed(true);
  const Dyn::State xd = x;
  Dyn::State nd(64);
  Eigen::internal::set_is_malloc_allowed(false);
  CHECK_THROWS_AS(dyn.step(xd, u, nd), std::logic_error);
  Eigen::internal::set_is_malloc_allowed(true);
}

TEST_CASE("schrodinger: bad input is rejected with a message", "[sim][quantum]") {
  using Dyn = sbptt::Schrodinger1D<double, Eigen::Dynamic>;
  CHECK_THROWS_AS(Dyn(0), sbptt::InvalidArgument);
  CHECK_THROWS_AS(Sim(31), sbptt::InvalidArgument);
  CHECK_THROWS_AS(Sim({-0.1, 128, 2.0}), sbptt::InvalidArgument);
  CHECK_THROWS_AS(Sim({0.0625, 0, 2.0}), sbptt::InvalidArgument);
  CHECK_THROWS_AS(Sim({0.0625, 128, std::nan("")}), sbptt::InvalidArgument);
  CHECK_THROWS_WITH(Sim({0.0625, 128, -1.0}), Catch::Contains("length = -1"));
  const Dyn sim(6);
  Dyn::State wrong = Dyn::State::Zero(10), out;
  Control u = control(0.0);
  CHECK_THROWS_WITH(sim.step(wrong, u, out), Catch::Contains("expected 12"));
  CHECK_THROWS_AS(sbptt::quantum_objective(sim, 7), sbptt::InvalidArgument);
}

TEST_CASE("tridiagonal: the pivots' reciprocal against complex division, tiny to huge pivots",
          "[sim][quantum]") {
  // In float |z|² underflows below |z| ≈ 1e-19 and overflows above 1e19: there the inline
  // conj(z)/|z|² must give way to the library's scaled division.
  for (const double scale : {1e-30, 1e-20, 1e-3, 1.0, 7.5, 1e3, 1e18, 1e25}) {
    for (const auto& [re, im] : {std::pair{1.0, 0.0}, {0.0, -1.0}, {0.6, 0.8}, {-3.0, 2.0}}) {
      const std::complex<float> z(static_cast<float>(re * scale), static_cast<float>(im * scale));
      const std::complex<double> exact = 1.0 / std::complex<double>(z);
      const std::complex<float> got = sbptt::detail::reciprocal(z);
      INFO("z = " << z);
      REQUIRE(std::isfinite(got.real()));
      REQUIRE(std::isfinite(got.imag()));
      CHECK(std::abs(std::complex<double>(got) - exact) <= 4e-7 * std::abs(exact));
    }
  }
  CHECK(sbptt::detail::reciprocal(4.0) == 0.25);
}
