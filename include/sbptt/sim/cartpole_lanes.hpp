#pragma once
/// \file The reference cart pole (cartpole_reference.hpp) over a block of samples in SIMD lanes,
/// for `CartPole::step_batch` and `vjp_batch` in float and double.
///
/// Equations and state layout (x, ẋ, θ_1, θ̇_1, …, θ_P, θ̇_P; control F): cartpole_reference.hpp.
/// A step is P pole updates, each from its own θ_i, θ̇_i and F, and one cart update from the
/// sum of the poles' terms, Σ_i q_i; the VJP likewise sums the poles' terms of Bᵀλ.
///
/// Two layouts of a block (lane_rows.hpp), the same numbers in both:
/// - a lane per sample: one pass of the pole equations per pole, over up to L samples (the
///   lanes of a block: 16 floats, 8 doubles);
/// - a lane per pole and sample (lane b·P + i): one pass for L / P samples, taken where it
///   needs fewer passes than P (`pole_lanes_pay`): in float, a thread's part of the paper's
///   batch, 4 samples of 4 poles, in one pass instead of four, the batch of 8 in two; in
///   double, the 4 samples in two passes.
/// Every lane runs the same arithmetic in both, and the sums over the poles are taken per
/// sample in pole order in both, so the two give the same numbers bit for bit
/// (tests/test_sim_cartpole_batch.cpp).
#include <algorithm>

#include "sbptt/core/types.hpp"
#include "sbptt/sim/cartpole_reference.hpp"
#include "sbptt/sim/lane_rows.hpp"

namespace sbptt::detail {

/// `model` with `poles` poles over samples first … first + count − 1 of a batch (count ≤ the
/// lanes of a block).
template <class Scalar>
struct CartPoleLanes {
  using Lanes = LaneRows<Scalar>;
  using Values = typename Lanes::Values;

  CartPoleReference<Scalar> model;  // a copy: a store into a batch cannot change it
  Index poles;

  /// x_next's columns (state_dim rows) from x's and u's.
  void step(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next,
            Index first, int count) const {
    if (pole_lanes_pay(count)) {
      for_pole_blocks(first, count, [&](Index block_first, int block_count) {
        step_pole_lanes(x, u, x_next, block_first, block_count);
      });
      return;
    }
    auto load = [&](const Matrix<Scalar>& m, Index row) {
      return Lanes::load(m, row, first, count);
    };
    const Values force = load(u, 0);
    Values q_sum = Values::Zero(), position, velocity;
    for (Index i = 0; i < poles; ++i) {
      const Index k = 2 + 2 * i;
      q_sum += model.pole_step(load(x, k), load(x, k + 1), force, position, velocity);
      Lanes::store(position, x_next, k, first, count);
      Lanes::store(velocity, x_next, k + 1, first, count);
    }
    model.cart_step(load(x, 0), load(x, 1), force, q_sum, position, velocity);
    Lanes::store(position, x_next, 0, first, count);
    Lanes::store(velocity, x_next, 1, first, count);
  }

  /// The columns of Aᵀλ (into `lambda_x` if not null) and Bᵀλ (into `lambda_u` if not null).
  void vjp(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const Matrix<Scalar>& lambda,
           Matrix<Scalar>* lambda_x, Matrix<Scalar>* lambda_u, Index first, int count) const {
    if (pole_lanes_pay(count)) {
      for_pole_blocks(first, count, [&](Index block_first, int block_count) {
        vjp_pole_lanes(x, u, lambda, lambda_x, lambda_u, block_first, block_count);
      });
      return;
    }
    auto load = [&](const Matrix<Scalar>& m, Index row) {
      return Lanes::load(m, row, first, count);
    };
    const Scalar dt = model.dt, dt2 = dt * dt;
    const Values force = load(u, 0), lambda_position = load(lambda, 0);
    const Values lambda_velocity = load(lambda, 1);
    const Values cart_adj = dt2 * lambda_position + dt * lambda_velocity;
    Values force_adj = model.inv_total_mass * cart_adj, theta_out, omega_out;
    for (Index i = 0; i < poles; ++i) {
      const Index k = 2 + 2 * i;
      force_adj += model.pole_vjp(load(x, k), load(x, k + 1), force, load(lambda, k),
                                  load(lambda, k + 1), cart_adj,
                                  lambda_x ? &theta_out : nullptr,
                                  lambda_x ? &omega_out : nullptr);
      if (lambda_x == nullptr) continue;
      Lanes::store(theta_out, *lambda_x, k, first, count);
      Lanes::store(omega_out, *lambda_x, k + 1, first, count);
    }
    if (lambda_x != nullptr) {
      Lanes::store(lambda_position, *lambda_x, 0, first, count);
      Lanes::store(dt * lambda_position + lambda_velocity, *lambda_x, 1, first, count);
    }
    if (lambda_u != nullptr) Lanes::store(force_adj, *lambda_u, 0, first, count);
  }

private:
  /// Samples per block with a lane per pole and sample, 0 if P is more than a block.
  [[nodiscard]] int pole_lane_samples() const { return static_cast<int>(Lanes::kLanes / poles); }

  /// Whether `count` samples fill fewer blocks with a lane per pole and sample than the P
  /// passes of a lane per sample.
  [[nodiscard]] bool pole_lanes_pay(int count) const {
    const int per_block = pole_lane_samples();
    return per_block > 0 && (count + per_block - 1) / per_block < poles;
  }

  /// f(first sample, samples) for each block of a lane per pole and sample that covers
  /// samples first … first + count − 1.
  template <class F>
  void for_pole_blocks(Index first, int count, F&& f) const {
    for (int done = 0; done < count; done += pole_lane_samples())
      f(first + done, std::min(pole_lane_samples(), count - done));
  }

  /// Row `offset` (0: θ_i, 1: θ̇_i) of every pole of samples first … first + count − 1 of `m`
  /// into lanes b·P + i; the other lanes are 0, as in `LaneRows::load`.
  [[nodiscard]] Values load_pole_lanes(const Matrix<Scalar>& m, Index offset, Index first,
                                       int count) const {
    Values v = Values::Zero();
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles; ++i) v(b * poles + i) = m(2 + 2 * i + offset, first + b);
    return v;
  }

  void store_pole_lanes(const Values& v, Matrix<Scalar>& m, Index offset, Index first,
                        int count) const {
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles; ++i) m(2 + 2 * i + offset, first + b) = v(b * poles + i);
  }

  /// Each sample's value (`per_sample`, lane b) in all of its pole lanes b·P + i.
  [[nodiscard]] Values spread_to_poles(const Values& per_sample, int count) const {
    Values v = Values::Zero();
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles; ++i) v(b * poles + i) = per_sample(b);
    return v;
  }

  /// `sum` (lane b: sample b) += the pole lanes b·P + i of `terms`, in pole order.
  void add_pole_lanes(const Values& terms, int count, Values& sum) const {
    for (int b = 0; b < count; ++b)
      for (Index i = 0; i < poles; ++i) sum(b) += terms(b * poles + i);
  }

  void step_pole_lanes(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next,
                       Index first, int count) const {
    const Values theta = load_pole_lanes(x, 0, first, count);
    const Values omega = load_pole_lanes(x, 1, first, count);
    const Values force = Lanes::load(u, 0, first, count);
    Values position, velocity;
    const Values q = model.pole_step(theta, omega, spread_to_poles(force, count), position,
                                     velocity);
    store_pole_lanes(position, x_next, 0, first, count);
    store_pole_lanes(velocity, x_next, 1, first, count);
    Values q_sum = Values::Zero();
    add_pole_lanes(q, count, q_sum);
    model.cart_step(Lanes::load(x, 0, first, count), Lanes::load(x, 1, first, count), force,
                    q_sum, position, velocity);
    Lanes::store(position, x_next, 0, first, count);
    Lanes::store(velocity, x_next, 1, first, count);
  }

  void vjp_pole_lanes(const Matrix<Scalar>& x, const Matrix<Scalar>& u,
                      const Matrix<Scalar>& lambda, Matrix<Scalar>* lambda_x,
                      Matrix<Scalar>* lambda_u, Index first, int count) const {
    const Scalar dt = model.dt, dt2 = dt * dt;
    const Values force = Lanes::load(u, 0, first, count);
    const Values lambda_position = Lanes::load(lambda, 0, first, count);
    const Values lambda_velocity = Lanes::load(lambda, 1, first, count);
    const Values cart_adj = dt2 * lambda_position + dt * lambda_velocity;
    Values force_adj = model.inv_total_mass * cart_adj, theta_out, omega_out;
    const Values theta = load_pole_lanes(x, 0, first, count);
    const Values omega = load_pole_lanes(x, 1, first, count);
    const Values lambda_theta = load_pole_lanes(lambda, 0, first, count);
    const Values lambda_omega = load_pole_lanes(lambda, 1, first, count);
    const Values force_terms = model.pole_vjp(
        theta, omega, spread_to_poles(force, count), lambda_theta, lambda_omega,
        spread_to_poles(cart_adj, count), lambda_x ? &theta_out : nullptr,
        lambda_x ? &omega_out : nullptr);
    add_pole_lanes(force_terms, count, force_adj);
    if (lambda_x != nullptr) {
      store_pole_lanes(theta_out, *lambda_x, 0, first, count);
      store_pole_lanes(omega_out, *lambda_x, 1, first, count);
      Lanes::store(lambda_position, *lambda_x, 0, first, count);
      Lanes::store(dt * lambda_position + lambda_velocity, *lambda_x, 1, first, count);
    }
    if (lambda_u != nullptr) Lanes::store(force_adj, *lambda_u, 0, first, count);
  }
};

}  // namespace sbptt::detail
