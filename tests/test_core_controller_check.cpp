// check_controller must catch what it exists to catch: a correct controller passes at
// round-off, and an error planted in any product the engine may run (plain, packed, the split
// halves, the scaled parameter product, the forward pass in ranges of columns) is reported in
// its own field at about its relative size.
#include <cmath>
#include <limits>

#include <catch2/catch.hpp>

#include "sbptt/core/controller_check.hpp"
#include "sbptt/nn/init.hpp"
#include "sbptt/nn/network.hpp"
#include "polynomial_policy.hpp"

using namespace sbptt;
using sbptt::testing::PolynomialPolicy;

namespace {

/// The toy policy with its parameter or input product scaled by (1 + size).
struct WrongBackward : PolynomialPolicy<double> {
  bool wrong_params, wrong_input;
  double size;
  WrongBackward(bool params, bool input, double s)
      : PolynomialPolicy<double>({2, 1}), wrong_params(params), wrong_input(input), size(s) {}
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx) const {
    Vector<double> own = Vector<double>::Zero(grad.size());
    PolynomialPolicy<double>::backward(ws, dy, own, dx);
    grad += wrong_params ? Vector<double>((1 + size) * own) : own;
    if (wrong_input && dx) *dx *= 1 + size;
  }
};

/// The toy policy with packed overloads (the packed weights are a copy of θ), one of them
/// planted wrong by the factor (1 + size): what a user's packing controller can get wrong.
struct WrongPacked : PolynomialPolicy<double> {
  enum class Where { Nowhere, Forward, ParamVjp, InputVjp } where;
  double size;
  struct PackedWeights {
    Vector<double> theta;
  };
  WrongPacked(Where w, double s) : PolynomialPolicy<double>({2, 1}), where(w), size(s) {}
  using PolynomialPolicy<double>::forward;
  using PolynomialPolicy<double>::backward;
  void pack(PackedWeights& packed) const { packed.theta = params(); }
  void forward(const Matrix<double>& x, Matrix<double>& y, Workspace& ws,
               const PackedWeights& packed) const {
    REQUIRE(packed.theta == params());  // packed after the last change of θ
    forward(x, y, ws);
    if (where == Where::Forward) y *= 1 + size;
  }
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx, const PackedWeights&) const {
    Vector<double> own = Vector<double>::Zero(grad.size());
    backward(ws, dy, own, dx);
    grad += where == Where::ParamVjp ? Vector<double>((1 + size) * own) : own;
    if (where == Where::InputVjp && dx) *dx *= 1 + size;
  }
};
static_assert(PackingController<WrongPacked>);

/// A `Network` with every optional path of the engine, one of them wrong: its result scaled
/// by (1 + size); or (ColumnPlace) a range of columns also written into the workspace at
/// column 0, or (ColumnUnwritten) not written into it at all, which leaves the outputs right
/// and the recorded activations wrong; or (SplitInputUnwritten) dX never written.
class PlantedNetwork {
public:
  enum class Where {
    Nowhere,
    SplitParams,
    SplitInput,
    SplitInputUnwritten,
    ScaledParams,
    ColumnOutputs,
    ColumnPlace,
    ColumnUnwritten
  };
  using Scalar = double;
  using Workspace = Network<double>::Workspace;
  using PackedWeights = Network<double>::PackedWeights;
  using LayerAdjoints = Network<double>::LayerAdjoints;

  PlantedNetwork(Network<double> net, Where where, double size)
      : net_(std::move(net)), where_(where), size_(size) {}

  Index input_dim() const { return net_.input_dim(); }
  Index output_dim() const { return net_.output_dim(); }
  Index num_params() const { return net_.num_params(); }
  const Vector<double>& params() const { return net_.params(); }
  Vector<double>& params() { return net_.params(); }

  void pack(PackedWeights& packed) const { net_.pack(packed); }
  void forward(const Matrix<double>& x, Matrix<double>& y, Workspace& ws) const {
    net_.forward(x, y, ws);
  }
  void forward(const Matrix<double>& x, Matrix<double>& y, Workspace& ws,
               const PackedWeights& packed) const {
    net_.forward(x, y, ws, packed);
  }
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx) const {
    net_.backward(ws, dy, grad, dx);
  }
  void backward(const Workspace& ws, const Matrix<double>& dy, Vector<double>& grad,
                Matrix<double>* dx, const PackedWeights& packed) const {
    net_.backward(ws, dy, grad, dx, packed);
  }
  void size_forward(Index batch, Workspace& ws) const { net_.size_forward(batch, ws); }
  void forward_columns(const Matrix<double>& x, Index first, Matrix<double>& y, Workspace& ws,
                       const PackedWeights& packed) const {
    if (where_ == Where::ColumnUnwritten && first > 0) {
      Workspace own;  // the outputs, without the workspace's columns
      net_.forward(x, y, own, packed);
      return;
    }
    net_.forward_columns(x, first, y, ws, packed);
    if (first == 0) return;
    if (where_ == Where::ColumnOutputs) y *= 1 + size_;
    if (where_ == Where::ColumnPlace) net_.forward_columns(x, 0, y, ws, packed);
  }
  void backward_inputs(const Workspace& ws, const Matrix<double>& dy, Matrix<double>* dx,
                       const PackedWeights& packed, LayerAdjoints& adjoints) const {
    const bool write_dx = where_ != Where::SplitInputUnwritten;
    net_.backward_inputs(ws, dy, write_dx ? dx : nullptr, packed, adjoints);
    if (where_ == Where::SplitInput && dx != nullptr) *dx *= 1 + size_;
  }
  void add_param_gradient(const Workspace& ws, const LayerAdjoints& adjoints,
                          Vector<double>& grad) const {
    Vector<double> own = Vector<double>::Zero(grad.size());
    net_.add_param_gradient(ws, adjoints, own);
    grad += (where_ == Where::SplitParams ? 1 + size_ : 1.0) * own;
  }
  void add_param_gradient(const Workspace& ws, const LayerAdjoints& adjoints,
                          const Matrix<double>& scales, LayerAdjoints& scaled,
                          Vector<double>& grad) const {
    Vector<double> own = Vector<double>::Zero(grad.size());
    net_.add_param_gradient(ws, adjoints, scales, scaled, own);
    grad += (where_ == Where::ScaledParams ? 1 + size_ : 1.0) * own;
  }

private:
  Network<double> net_;
  Where where_;
  double size_;
};
static_assert(SeedScalingController<PlantedNetwork> && ColumnSplitController<PlantedNetwork>);

Network<double> small_network() {
  auto net = Network<double>::mlp(3, {5, 4}, 1);
  Rng rng(7);
  glorot_uniform(net, rng);  // the last kernel random too: no product is trivially 0
  return net;
}

Matrix<double> small_batch() {
  Matrix<double> x(3, 4);
  x << 0.3, -0.8, 1.1, 0.2, -0.5, 0.7, 0.1, -1.3, 0.9, 0.4, -0.2, 0.6;
  return x;
}

}  // namespace

TEST_CASE("check_controller passes a correct controller and names each planted error",
          "[core][controller_check]") {
  Matrix<double> inputs(1, 3);
  inputs << -0.3, 0.8, 1.5;
  for (bool params : {false, true}) {
    for (bool input : {false, true}) {
      WrongBackward policy(params, input, 1e-4);
      policy.params() << 0.7, -1.2;
      const auto check = check_controller(policy, inputs);
      INFO("wrong params " << params << ", wrong input " << input);
      if (params) CHECK(check.param_vjp_error == Approx(1e-4).epsilon(1e-2));
      else CHECK(check.param_vjp_error < 1e-9);
      if (input) CHECK(check.input_vjp_error == Approx(1e-4).epsilon(1e-2));
      else CHECK(check.input_vjp_error < 1e-9);
    }
  }
}

TEST_CASE("check_controller checks a packing controller's packed overloads, the ones the engine "
          "runs", "[core][controller_check]") {
  using Where = WrongPacked::Where;
  Matrix<double> inputs(1, 3);
  inputs << -0.3, 0.8, 1.5;
  for (Where where : {Where::Nowhere, Where::Forward, Where::ParamVjp, Where::InputVjp}) {
    WrongPacked policy(where, 1e-4);
    policy.params() << 0.7, -1.2;
    const auto check = check_controller(policy, inputs);
    INFO("planted in " << static_cast<int>(where));
    CHECK(check.has_packed);
    CHECK(check.param_vjp_error < 1e-9);  // the plain path is right in every case
    CHECK(check.input_vjp_error < 1e-9);
    auto expect = [&](Where at, double error) {
      if (where == at) CHECK(error == Approx(1e-4).epsilon(1e-2));
      else CHECK(error < 1e-9);
    };
    expect(Where::Forward, check.packed_forward_error);
    expect(Where::ParamVjp, check.packed_param_vjp_error);
    expect(Where::InputVjp, check.packed_input_vjp_error);
    if (where == Where::Nowhere) CHECK(check.worst() < 1e-9);
    else CHECK(check.worst() == Approx(1e-4).epsilon(1e-2));
  }
  WrongBackward plain(false, false, 0);
  CHECK_FALSE(check_controller(plain, inputs).has_packed);
}

TEST_CASE("check_controller checks the engine's optional paths of a network, each on its own",
          "[core][controller_check]") {
  using Where = PlantedNetwork::Where;
  const double size = 1e-4;
  for (Where where : {Where::Nowhere, Where::SplitParams, Where::SplitInput,
                      Where::SplitInputUnwritten, Where::ScaledParams, Where::ColumnOutputs,
                      Where::ColumnPlace, Where::ColumnUnwritten}) {
    INFO("planted in " << static_cast<int>(where));
    PlantedNetwork net(small_network(), where, size);
    const auto check = check_controller(net, small_batch());
    CHECK((check.has_packed && check.has_split_backward && check.has_seed_scaling &&
           check.has_column_split));
    // The plain and packed paths are the network's own in every case.
    CHECK(worst_error({check.param_vjp_error, check.input_vjp_error, check.packed_forward_error,
                       check.packed_param_vjp_error, check.packed_input_vjp_error}) < 1e-8);
    auto expect = [&](Where at, double error) {
      if (where == at) CHECK(error == Approx(size).epsilon(1e-2));
      else CHECK(error < 1e-8);
    };
    expect(Where::SplitParams, check.split_param_vjp_error);
    if (where == Where::SplitInputUnwritten) CHECK(std::isinf(check.split_input_vjp_error));
    else expect(Where::SplitInput, check.split_input_vjp_error);
    expect(Where::ScaledParams, check.scaled_param_vjp_error);
    if (where == Where::ColumnOutputs) {
      // size · |y_b| / max |y| over the columns past the cut: at most size
      CHECK(check.column_split_forward_error > 0.1 * size);
      CHECK(check.column_split_forward_error <= size * (1 + 1e-9));
    } else {
      CHECK(check.column_split_forward_error == 0);  // a network's parts: bit for bit
    }
    if (where == Where::ColumnPlace || where == Where::ColumnUnwritten)
      CHECK(check.column_split_backward_error > 1e-2);
    else CHECK(check.column_split_backward_error < 1e-8);
    if (where == Where::Nowhere) CHECK(check.worst() < 1e-8);
    else CHECK(check.worst() > 0.5 * size);
  }
}

TEST_CASE("check_controller's worst() is NaN when any product is NaN", "[core][controller_check]") {
  Matrix<double> inputs(1, 3);
  inputs << -0.3, 0.8, 1.5;
  WrongPacked policy(WrongPacked::Where::InputVjp, std::numeric_limits<double>::quiet_NaN());
  policy.params() << 0.7, -1.2;
  const auto check = check_controller(policy, inputs);
  CHECK(std::isnan(check.packed_input_vjp_error));
  CHECK(check.param_vjp_error < 1e-9);
  CHECK(std::isnan(check.worst()));
  // The worst over the cuts of a batch keeps a NaN too.
  PlantedNetwork net(small_network(), PlantedNetwork::Where::ColumnOutputs,
                     std::numeric_limits<double>::quiet_NaN());
  const auto parts = check_controller(net, small_batch());
  CHECK(std::isnan(parts.column_split_forward_error));
  CHECK(std::isnan(parts.worst()));
}
