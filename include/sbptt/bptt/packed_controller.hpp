#pragma once
/// \file A controller as the engine calls it: with its parameters packed once per rollout when
/// it is a `PackingController` (and plainly otherwise), with its forward pass in parts of the
/// batch when it is a `ColumnSplitController`, and with its backward split into an input half
/// and a parameter half when it is a `SplitBackwardController`. Implementation detail of
/// `sbptt::Engine`.
#include "sbptt/core/concepts.hpp"
#include "sbptt/core/types.hpp"

namespace sbptt::detail {

/// Stands in for a type the controller does not have.
struct Absent {};

/// `C::PackedWeights` for a `PackingController`, else `Absent`.
template <class C, bool = PackingController<C>>
struct PackedWeightsOf {
  using Type = Absent;
};
template <class C>
struct PackedWeightsOf<C, true> {
  using Type = typename C::PackedWeights;
};

/// `C::LayerAdjoints` for a `SplitBackwardController`, else `Absent`.
template <class C, bool = SplitBackwardController<C>>
struct LayerAdjointsOf {
  using Type = Absent;
};
template <class C>
struct LayerAdjointsOf<C, true> {
  using Type = typename C::LayerAdjoints;
};

/// `Ctrl` with its packed weights: `pack` before a rollout, then the calls of the rollout and
/// of the sweeps over it use that packing.
template <class Ctrl>
class PackedController {
public:
  using Scalar = typename Ctrl::Scalar;
  using Workspace = typename Ctrl::Workspace;

  explicit PackedController(const Ctrl& controller) : controller_(controller) {}

  void pack() {
    if constexpr (PackingController<Ctrl>) controller_.pack(packed_);
  }

  void forward(const Matrix<Scalar>& x, Matrix<Scalar>& y, Workspace& ws) const {
    if constexpr (PackingController<Ctrl>) {
      controller_.forward(x, y, ws, packed_);
    } else {
      controller_.forward(x, y, ws);
    }
  }

  void size_forward(Index batch, Workspace& ws) const
    requires ColumnSplitController<Ctrl>
  {
    controller_.size_forward(batch, ws);
  }

  void forward_columns(const Matrix<Scalar>& x, Index first, Matrix<Scalar>& y,
                       Workspace& ws) const
    requires ColumnSplitController<Ctrl>
  {
    controller_.forward_columns(x, first, y, ws, packed_);
  }

  void backward(const Workspace& ws, const Matrix<Scalar>& dy, Vector<Scalar>& grad,
                Matrix<Scalar>* dx) const {
    if constexpr (PackingController<Ctrl>) {
      controller_.backward(ws, dy, grad, dx, packed_);
    } else {
      controller_.backward(ws, dy, grad, dx);
    }
  }

  /// The input half of `backward`, recording what `add_param_gradient` needs.
  template <class Adjoints>
  void backward_inputs(const Workspace& ws, const Matrix<Scalar>& dy, Matrix<Scalar>* dx,
                       Adjoints& adjoints) const
    requires SplitBackwardController<Ctrl>
  {
    controller_.backward_inputs(ws, dy, dx, packed_, adjoints);
  }

private:
  const Ctrl& controller_;
  typename PackedWeightsOf<Ctrl>::Type packed_;
};

}  // namespace sbptt::detail
