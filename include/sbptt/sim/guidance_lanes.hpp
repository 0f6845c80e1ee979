#pragma once
/// \file The batch path of `GuidanceByRepulsion` (float, fixed agent counts): blocks of samples
/// side by side in SIMD lanes, one lane array per state or control row (lane_rows.hpp), through
/// the simulator's own equations on a sample's numbers, `step_values` and `vjp_values`.
/// Equations and state layout: guidance_by_repulsion.hpp. Implementation detail of its
/// `step_batch`, `vjp_batch` and `vjp_batch_pair`, with their argument checks; how the lanes
/// round is in `step_batch`'s documentation.
#include <array>
#include <cstddef>
#include <type_traits>

#include <Eigen/Core>

#include "sbptt/core/error.hpp"
#include "sbptt/core/types.hpp"
#include "sbptt/core/unroll.hpp"
#include "sbptt/sim/lane_rows.hpp"
#include "sbptt/sim/side_by_side.hpp"

namespace sbptt::detail {

/// The batch calls of a `GuidanceByRepulsion`, `Sim`, which befriends this class.
template <class Sim>
class GuidanceLanes {
public:
  using Scalar = typename Sim::Scalar;
  using Lanes = LaneRows<Scalar>;
  static_assert(std::is_same_v<Scalar, float> && Sim::kStateSize != Eigen::Dynamic,
                "GuidanceLanes: float with fixed agent counts only, as step_batch requires");

  explicit GuidanceLanes(const Sim& sim) : sim_(sim) {}

  /// `Sim::step_batch`.
  void step(const Matrix<Scalar>& x, const Matrix<Scalar>& u, Matrix<Scalar>& x_next) const {
    check_batch(x, u, "step_batch");
    x_next.resize(sim_.state_dim(), x.cols());
    RowLanes<Sim::kStateSize> state, next;
    RowLanes<Sim::kControlSize> control;
    RowLanes<2 * Sim::kAgents> acc;
    for (Index first = 0; first < x.cols(); first += Lanes::kLanes) {
      const int count = Lanes::count(x.cols(), first);
      Lanes::load_rows(x, first, count, state);
      Lanes::load_rows(u, first, count, control);
      sim_.step_values(state.data(), control.data(), acc.data(), next.data());
      Lanes::store_rows(next, first, count, x_next);
    }
  }

  /// `Sim::vjp_batch`.
  void vjp(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const Matrix<Scalar>& lambda,
           Matrix<Scalar>* lambda_x, Matrix<Scalar>* lambda_u) const {
    check_batch(x, u, "vjp_batch");
    check_adjoint(lambda, x, "vjp_batch", "lambda");
    if (lambda_x != nullptr) lambda_x->resize(sim_.state_dim(), x.cols());
    if (lambda_u != nullptr) lambda_u->resize(sim_.control_dim(), x.cols());
    vjp_blocks({&x}, {&u}, {&lambda}, {lambda_x}, {lambda_u});
  }

  /// `Sim::vjp_batch_pair`.
  void vjp_pair(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const Matrix<Scalar>& lambda_1,
                const Matrix<Scalar>& lambda_2, Matrix<Scalar>* lambda_x_1,
                Matrix<Scalar>* lambda_x_2, Matrix<Scalar>* lambda_u_1,
                Matrix<Scalar>* lambda_u_2) const {
    check_batch(x, u, "vjp_batch_pair");
    check_adjoint(lambda_1, x, "vjp_batch_pair", "lambda_1");
    check_adjoint(lambda_2, x, "vjp_batch_pair", "lambda_2");
    size_paired_outputs("GuidanceByRepulsion::vjp_batch_pair", x, u, lambda_1, lambda_2,
                        {lambda_x_1, lambda_x_2}, {lambda_u_1, lambda_u_2}, sim_.state_dim(),
                        sim_.control_dim());
    vjp_blocks({&x, &x}, {&u, &u}, {&lambda_1, &lambda_2}, {lambda_x_1, lambda_x_2},
               {lambda_u_1, lambda_u_2});
  }

private:
  template <int Rows>
  using RowLanes = std::array<typename Lanes::Values, static_cast<std::size_t>(Rows)>;
  using Columns = typename Lanes::Columns;
  using ColumnsOut = typename Lanes::ColumnsOut;

  /// An output without a matrix is skipped. One machine copy (SBPTT_ONE_COPY) for `vjp` and
  /// `vjp_pair`, so that the pair's halves are the single calls' bits.
  SBPTT_ONE_COPY void vjp_blocks(const Columns& x, const Columns& u, const Columns& lambda,
                                 const ColumnsOut& lambda_x, const ColumnsOut& lambda_u) const {
    RowLanes<Sim::kStateSize> state, cotangent, propagated;
    RowLanes<Sim::kControlSize> control, control_cotangent;
    const Index columns = lambda.cols();
    for (Index first = 0; first < columns; first += Lanes::kLanes) {
      const int count = Lanes::count(columns, first);
      Lanes::load_rows(x, first, count, state);
      Lanes::load_rows(u, first, count, control);
      Lanes::load_rows(lambda, first, count, cotangent);
      sim_.vjp_values(state.data(), control.data(), cotangent.data(),
                      lambda_x.left ? propagated.data() : nullptr,
                      lambda_u.left ? control_cotangent.data() : nullptr);
      if (lambda_x.left) Lanes::store_rows(propagated, first, count, lambda_x);
      if (lambda_u.left) Lanes::store_rows(control_cotangent, first, count, lambda_u);
    }
  }

  void check_batch(const Matrix<Scalar>& x, const Matrix<Scalar>& u, const char* caller) const {
    require(x.rows() == sim_.state_dim(), "GuidanceByRepulsion::", caller, ": x has ", x.rows(),
            " rows; expected state_dim() = ", sim_.state_dim(), " (one sample per column)");
    require(u.rows() == sim_.control_dim() && u.cols() == x.cols(), "GuidanceByRepulsion::",
            caller, ": u is ", u.rows(), " x ", u.cols(), "; expected ", sim_.control_dim(),
            " x ", x.cols(), " (one control per sample)");
  }

  void check_adjoint(const Matrix<Scalar>& lambda, const Matrix<Scalar>& x, const char* caller,
                     const char* name) const {
    require(lambda.rows() == sim_.state_dim() && lambda.cols() == x.cols(),
            "GuidanceByRepulsion::", caller, ": ", name, " is ", lambda.rows(), " x ",
            lambda.cols(), "; expected ", sim_.state_dim(), " x ", x.cols());
  }

  const Sim& sim_;
};

}  // namespace sbptt::detail
