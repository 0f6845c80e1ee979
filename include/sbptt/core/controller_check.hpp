#pragma once
/// \file `check_controller`: the finite-difference twin of a controller's backward pass, and
/// of every optional path the engine takes through it.
///
/// The reference is a central difference of the pairing s_b(θ, X) = ⟨dY_b, N(x_b; θ)⟩ of each
/// sample b with a seeded random output adjoint dY, in θ and in X (finite_difference.hpp for
/// the step and the error measure). Per sample, so that one set of differences serves every
/// seed the engine uses: Σ_b ∂s_b/∂θ for dY, Σ_b σ_b ∂s_b/∂θ for the column-scaled seed
/// dY·diag(σ) of a `SeedScalingController`.
///
/// The engine runs a controller's optional overloads, not its plain `backward`: the packed
/// ones (`PackingController`), the two halves (`SplitBackwardController`), the scaled
/// parameter products (`SeedScalingController`) and the forward pass in ranges of columns
/// (`ColumnSplitController`). A user's optional path that disagrees with the plain one would
/// train on a wrong gradient that every check of the plain path passes, so each is checked
/// here against the same differences.
#include <cstdint>
#include <initializer_list>
#include <utility>

#include "sbptt/core/concepts.hpp"
#include "sbptt/core/finite_difference.hpp"
#include "sbptt/core/rng.hpp"

namespace sbptt {

/// Result of `check_controller`: worst relative errors of each product the controller offers.
/// Tolerances that hold for the library's `Network` at the default step: `worst() < 1e-6` in
/// double. A `ColumnSplitController` whose `column_split_forward_error` is not exactly 0
/// still trains, but its results then depend on the number of threads.
template <class Scalar>
struct ControllerCheck {
  Scalar param_vjp_error = 0;  ///< backward's parameter product against finite differences
  Scalar input_vjp_error = 0;  ///< backward's input product against finite differences
  bool has_packed = false;     ///< the controller packs its weights; the fields below are set
  Scalar packed_forward_error = 0;    ///< forward with packed weights against plain forward
  Scalar packed_param_vjp_error = 0;  ///< packed backward's parameter product against FD
  Scalar packed_input_vjp_error = 0;  ///< packed backward's input product against FD
  bool has_split_backward = false;    ///< `SplitBackwardController`: the two fields below
  Scalar split_param_vjp_error = 0;   ///< add_param_gradient after backward_inputs against FD
  Scalar split_input_vjp_error = 0;   ///< backward_inputs' input product against FD
  bool has_seed_scaling = false;      ///< `SeedScalingController`: the field below
  Scalar scaled_param_vjp_error = 0;  ///< the scaled parameter product (seed dY·diag(σ)) vs FD
  /// `ColumnSplitController` and a batch of at least 2 (a cut to check): the fields below
  bool has_column_split = false;
  /// Outputs of the batch rolled forward in two ranges of columns, every cut, against the
  /// packed forward of the whole batch (0 when a sample does not depend on its neighbours).
  Scalar column_split_forward_error = 0;
  /// The packed backward over a workspace filled in two ranges, every cut, against FD (both
  /// products): a range written at the wrong columns passes the forward check and fails here.
  Scalar column_split_backward_error = 0;
  /// The largest error, or NaN if any is NaN.
  [[nodiscard]] Scalar worst() const {
    return worst_error(
        {param_vjp_error, input_vjp_error, packed_forward_error, packed_param_vjp_error,
         packed_input_vjp_error, split_param_vjp_error, split_input_vjp_error,
         scaled_param_vjp_error, column_split_forward_error, column_split_backward_error});
  }
};

/// Checks `ctrl.backward` at the batch `inputs` (input_dim × B) and every optional path of
/// the file comment that the controller offers. The parameters are perturbed in place and
/// restored.
template <Controller Ctrl>
[[nodiscard]] ControllerCheck<typename Ctrl::Scalar> check_controller(
    Ctrl& ctrl, const Matrix<typename Ctrl::Scalar>& inputs, std::uint64_t seed = 1,
    typename Ctrl::Scalar step = default_fd_step<typename Ctrl::Scalar>()) {
  using Scalar = typename Ctrl::Scalar;
  const Index batch = inputs.cols();
  Rng rng(seed);
  Matrix<Scalar> outputs;
  typename Ctrl::Workspace ws;
  ctrl.forward(inputs, outputs, ws);
  Matrix<Scalar> adjoint(outputs.rows(), outputs.cols());
  for (Index i = 0; i < adjoint.size(); ++i) adjoint(i) = static_cast<Scalar>(rng.normal());

  Vector<Scalar> grad = Vector<Scalar>::Zero(ctrl.num_params());
  Matrix<Scalar> input_adjoint;
  ctrl.backward(ws, adjoint, grad, &input_adjoint);

  auto pairings = [&](const Matrix<Scalar>& x, Vector<Scalar>& per_sample) {
    typename Ctrl::Workspace probe_ws;
    Matrix<Scalar> y;
    ctrl.forward(x, y, probe_ws);
    per_sample = (adjoint.array() * y.array()).colwise().sum().transpose();
  };
  const Vector<Scalar> theta = ctrl.params();
  auto in_params = [&](const Vector<Scalar>& p, Vector<Scalar>& out) {
    ctrl.params() = p;
    pairings(inputs, out);
  };
  // Row b: ∂s_b/∂θ.
  const Matrix<Scalar> fd_per_sample =
      finite_difference_jacobian<Scalar>(in_params, theta, batch, step);
  ctrl.params() = theta;
  const Matrix<Scalar> fd_params = fd_per_sample.colwise().sum().transpose();

  auto in_inputs = [&](const Vector<Scalar>& flat, Vector<Scalar>& out) {
    Vector<Scalar> per_sample;
    pairings(flat.reshaped(inputs.rows(), inputs.cols()), per_sample);
    out.resize(1);
    out(0) = per_sample.sum();
  };
  const Vector<Scalar> flat_inputs = inputs.reshaped();
  const Matrix<Scalar> fd_inputs =
      finite_difference_jacobian<Scalar>(in_inputs, flat_inputs, 1, step).transpose();
  auto input_error = [&](const Matrix<Scalar>& dx) {
    return relative_error<Scalar>(Matrix<Scalar>(dx.reshaped()), fd_inputs);
  };

  ControllerCheck<Scalar> result;
  result.param_vjp_error = relative_error<Scalar>(grad, fd_params);
  result.input_vjp_error = input_error(input_adjoint);

  if constexpr (PackingController<Ctrl>) {
    result.has_packed = true;
    typename Ctrl::PackedWeights packed;
    ctrl.pack(packed);
    typename Ctrl::Workspace packed_ws;
    Matrix<Scalar> packed_outputs, packed_dx;
    ctrl.forward(inputs, packed_outputs, packed_ws, packed);
    result.packed_forward_error = relative_error<Scalar>(packed_outputs, outputs);
    Vector<Scalar> packed_grad = Vector<Scalar>::Zero(ctrl.num_params());
    ctrl.backward(packed_ws, adjoint, packed_grad, &packed_dx, packed);
    result.packed_param_vjp_error = relative_error<Scalar>(packed_grad, fd_params);
    result.packed_input_vjp_error = input_error(packed_dx);

    if constexpr (SplitBackwardController<Ctrl>) {
      result.has_split_backward = true;
      typename Ctrl::LayerAdjoints recorded;
      Matrix<Scalar> split_dx;  // its own: a call that never writes it must not pass
      ctrl.backward_inputs(packed_ws, adjoint, &split_dx, packed, recorded);
      Vector<Scalar> split_grad = Vector<Scalar>::Zero(ctrl.num_params());
      ctrl.add_param_gradient(packed_ws, recorded, split_grad);
      result.split_param_vjp_error = relative_error<Scalar>(split_grad, fd_params);
      result.split_input_vjp_error = input_error(split_dx);

      if constexpr (SeedScalingController<Ctrl>) {
        result.has_seed_scaling = true;
        Matrix<Scalar> scales(1, batch);
        for (Index b = 0; b < batch; ++b) scales(b) = static_cast<Scalar>(rng.normal());
        typename Ctrl::LayerAdjoints scaled;
        Vector<Scalar> scaled_grad = Vector<Scalar>::Zero(ctrl.num_params());
        ctrl.add_param_gradient(packed_ws, recorded, scales, scaled, scaled_grad);
        const Matrix<Scalar> fd_scaled = (scales * fd_per_sample).transpose();
        result.scaled_param_vjp_error = relative_error<Scalar>(scaled_grad, fd_scaled);
      }
    }

    if constexpr (ColumnSplitController<Ctrl>) {
      result.has_column_split = batch > 1;
      Matrix<Scalar> part_outputs, in_parts(outputs.rows(), batch), other_outputs;
      // Other inputs, rolled forward into the workspace before every cut: a column that the
      // parts leave unwritten then holds another sample's numbers, as it would in the engine
      // (the last rollout's), not this sample's from an earlier cut.
      const Matrix<Scalar> other_inputs = (Scalar(-0.5) * inputs.array() + Scalar(0.25)).matrix();
      typename Ctrl::Workspace parts_ws;
      for (Index cut = 1; cut < batch; ++cut) {
        ctrl.forward(other_inputs, other_outputs, parts_ws, packed);
        ctrl.size_forward(batch, parts_ws);
        for (const auto& [first, count] : {std::pair{Index{0}, cut}, {cut, batch - cut}}) {
          ctrl.forward_columns(inputs.middleCols(first, count), first, part_outputs, parts_ws,
                               packed);
          in_parts.middleCols(first, count) = part_outputs;
        }
        result.column_split_forward_error = worst_error(
            {result.column_split_forward_error, relative_error<Scalar>(in_parts, packed_outputs)});
        Vector<Scalar> parts_grad = Vector<Scalar>::Zero(ctrl.num_params());
        Matrix<Scalar> parts_dx;
        ctrl.backward(parts_ws, adjoint, parts_grad, &parts_dx, packed);
        result.column_split_backward_error =
            worst_error({result.column_split_backward_error,
                         relative_error<Scalar>(parts_grad, fd_params), input_error(parts_dx)});
      }
    }
  }
  return result;
}

}  // namespace sbptt
