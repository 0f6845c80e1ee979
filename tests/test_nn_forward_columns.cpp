// A network's forward pass in parts (`size_forward`, `forward_columns`), as the engine runs it
// on several threads: every part, however the batch is cut, gives the numbers of each sample
// evaluated alone (a batch of one), bit for bit, in the outputs and in every recorded layer
// output, and a backward pass over the workspace filled in parts gives the whole batch's
// (which reads the im2col matrices too); parts on two threads at once give the same. Being
// equal to the sample alone says nothing of the sample alone being right, so the forward pass
// is also held within round-off of a long-double evaluation. Layer widths leave partial
// registers, so the tanh runs on padded registers at every offset. The outputs may be written
// over the inputs.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdint>
#include <limits>
#include <thread>
#include <utility>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/nn/network.hpp"

using sbptt::Activation;
using sbptt::Index;
using sbptt::Matrix;
using sbptt::Network;
using sbptt::testing::random_matrix;
using Catch::Matchers::Contains;

namespace {

template <class S>
std::vector<Network<S>> networks() {
  std::vector<Network<S>> nets;
  nets.push_back(Network<S>::mlp(5, {7, 13}, 3));
  nets.push_back(Network<S>::mlp(10, {100, 100}, 1));
  nets.push_back(Network<S>({sbptt::Conv1d{11, 2, 5, 3, 2, Activation::Tanh},
                             sbptt::Dense{25, 9, Activation::Tanh}, sbptt::Dense{9, 2}}));
  std::uint64_t seed = 20;
  for (auto& net : nets) sbptt::testing::randomize(net, ++seed, 1.0);
  return nets;
}

template <class S>
bool same(const Matrix<S>& a, const Matrix<S>& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() && (a.array() == b.array()).all();
}

/// The cuts of a batch of 11 into parts: whole, halves, uneven, single columns.
std::vector<std::vector<Index>> cuts() {
  std::vector<Index> singles;
  for (Index b = 0; b <= 11; ++b) singles.push_back(b);
  return {{0, 11}, {0, 5, 11}, {0, 1, 4, 11}, {0, 3, 6, 9, 11}, singles};
}

}  // namespace

TEMPLATE_TEST_CASE("forward in parts: every sample as if alone, bit for bit", "[nn][columns]",
                   float, double) {
  using S = TestType;
  for (const auto& net : networks<S>()) {
    INFO(net.describe());
    const Matrix<S> x = random_matrix<S>(net.input_dim(), 11, 3, 2.0);
    typename Network<S>::PackedWeights packed;
    net.pack(packed);
    // Each sample alone: the truth the parts are held to.
    std::vector<typename Network<S>::Workspace> alone(11);
    Matrix<S> alone_y(net.output_dim(), 11), y1;
    for (Index b = 0; b < 11; ++b) {
      net.forward(x.col(b), y1, alone[static_cast<std::size_t>(b)], packed);
      alone_y.col(b) = y1;
    }
    for (const auto& cut : cuts()) {
      INFO("parts " << cut.size() - 1);
      typename Network<S>::Workspace ws;
      net.size_forward(11, ws);
      Matrix<S> y(net.output_dim(), 11), part_y;
      for (std::size_t k = 0; k + 1 < cut.size(); ++k) {
        const Index first = cut[k], count = cut[k + 1] - cut[k];
        net.forward_columns(x.middleCols(first, count), first, part_y, ws, packed);
        REQUIRE(part_y.cols() == count);
        y.middleCols(first, count) = part_y;
      }
      REQUIRE(same<S>(y, alone_y));
      for (Index l = 0; l < net.num_layers(); ++l)
        for (Index b = 0; b < 11; ++b)
          REQUIRE(same<S>(ws.layer_output(l).col(b),
                          alone[static_cast<std::size_t>(b)].layer_output(l)));
    }
    // The plain forward pass is the same too, and so is a backward pass over a workspace
    // filled in parts.
    Matrix<S> whole;
    typename Network<S>::Workspace whole_ws, parts_ws;
    net.forward(x, whole, whole_ws, packed);
    REQUIRE(same<S>(whole, alone_y));
    net.size_forward(11, parts_ws);
    Matrix<S> part_y;
    net.forward_columns(x.leftCols(4), 0, part_y, parts_ws, packed);
    net.forward_columns(x.rightCols(7), 4, part_y, parts_ws, packed);
    const Matrix<S> dy = random_matrix<S>(net.output_dim(), 11, 9, 1.0);
    sbptt::Vector<S> whole_grad = sbptt::Vector<S>::Zero(net.num_params());
    sbptt::Vector<S> parts_grad = whole_grad;
    Matrix<S> whole_dx, parts_dx;
    net.backward(whole_ws, dy, whole_grad, &whole_dx, packed);
    net.backward(parts_ws, dy, parts_grad, &parts_dx, packed);
    REQUIRE((whole_grad.array() == parts_grad.array()).all());
    REQUIRE(same<S>(whole_dx, parts_dx));
  }
}

TEMPLATE_TEST_CASE("forward in parts on two threads at once equals one pass", "[nn][columns]",
                   float, double) {
  using S = TestType;
  for (const auto& net : networks<S>()) {
    INFO(net.describe());
    const Matrix<S> x = random_matrix<S>(net.input_dim(), 64, 4, 1.0);
    typename Network<S>::PackedWeights packed;
    net.pack(packed);
    Matrix<S> whole;
    typename Network<S>::Workspace whole_ws;
    net.forward(x, whole, whole_ws, packed);
    const Matrix<S> left = x.leftCols(29), right = x.rightCols(35);
    for (int repeat = 0; repeat < 20; ++repeat) {
      typename Network<S>::Workspace ws;
      net.size_forward(64, ws);
      Matrix<S> left_y, right_y;
      std::thread other([&] { net.forward_columns(right, 29, right_y, ws, packed); });
      net.forward_columns(left, 0, left_y, ws, packed);
      other.join();
      REQUIRE(same<S>(left_y, whole.leftCols(29)));
      REQUIRE(same<S>(right_y, whole.rightCols(35)));
      for (Index l = 0; l < net.num_layers(); ++l)
        REQUIRE(same<S>(ws.layer_output(l), whole_ws.layer_output(l)));
    }
  }
}

TEMPLATE_TEST_CASE("the outputs may take the inputs' place", "[nn][columns]", float, double) {
  // forward(v, v, ws): the output is written into the matrix the input is read from, whether
  // or not the widths differ (the first network keeps 5, the others do not).
  using S = TestType;
  std::vector<Network<S>> nets = networks<S>();
  nets.insert(nets.begin(), Network<S>::mlp(5, {7}, 5));
  sbptt::testing::randomize(nets.front(), 19, 1.0);
  for (const auto& net : nets) {
    INFO(net.describe());
    const Matrix<S> x = random_matrix<S>(net.input_dim(), 6, 8, 1.0);
    Matrix<S> y;
    typename Network<S>::Workspace ws, in_place_ws;
    net.forward(x, y, ws);
    Matrix<S> v = x;
    net.forward(v, v, in_place_ws);
    REQUIRE(same<S>(v, y));
    for (Index l = 0; l < net.num_layers(); ++l)
      REQUIRE(same<S>(in_place_ws.layer_output(l), ws.layer_output(l)));
  }
}

TEMPLATE_TEST_CASE("the forward pass is within round-off of long double", "[nn][columns]", float,
                   double) {
  using S = TestType;
  // The MLP 5 → 7 → 13 → 3 with tanh, evaluated in long double from the same parameters.
  const Network<S> net = networks<S>()[0];
  const Matrix<S> x = random_matrix<S>(5, 11, 5, 2.0);
  Matrix<S> y;
  typename Network<S>::Workspace ws;
  net.forward(x, y, ws);
  using L = long double;
  Index offset = 0;
  Eigen::Matrix<L, Eigen::Dynamic, Eigen::Dynamic> a = x.template cast<L>();
  for (const auto& layer : net.layers()) {
    const auto& dense = std::get<sbptt::Dense>(layer);
    Eigen::Matrix<L, Eigen::Dynamic, Eigen::Dynamic> w(dense.outputs, dense.inputs);
    for (Index i = 0; i < dense.outputs; ++i)
      for (Index j = 0; j < dense.inputs; ++j)
        w(i, j) = net.params()(offset + i * dense.inputs + j);
    offset += dense.weight_count();
    Eigen::Matrix<L, Eigen::Dynamic, 1> bias = net.params().segment(offset, dense.outputs)
                                                   .template cast<L>();
    offset += dense.outputs;
    a = (w * a).colwise() + bias;
    if (dense.activation == Activation::Tanh) a = a.unaryExpr([](L v) { return std::tanh(v); });
  }
  const double eps = std::numeric_limits<S>::epsilon();
  REQUIRE((y.template cast<L>() - a).cwiseAbs().maxCoeff() <= L(200 * eps));
}

TEST_CASE("forward in parts refuses an unsized workspace and a range outside the batch",
          "[nn][columns]") {
  const Network<double> net = networks<double>()[0];
  typename Network<double>::PackedWeights packed;
  net.pack(packed);
  const Matrix<double> x = random_matrix<double>(5, 4, 6, 1.0);
  typename Network<double>::Workspace ws;
  Matrix<double> y;
  REQUIRE_THROWS_WITH(net.forward_columns(x, 0, y, ws, packed),
                      Contains("expected size_forward(B, ws) first"));
  REQUIRE_THROWS_WITH(net.size_forward(-1, ws), Contains("batch = -1"));
  typename Network<double>::Workspace other;
  Network<double>::mlp(5, {8}, 3).size_forward(6, other);
  REQUIRE_THROWS_WITH(net.forward_columns(x, 0, y, other, packed),
                      Contains("sized for another network"));
  net.size_forward(6, ws);
  REQUIRE_THROWS_WITH(net.forward_columns(x, 3, y, ws, packed),
                      Contains("samples 3 … 6") && Contains("within the 6 samples"));
  REQUIRE_THROWS_WITH(net.forward_columns(x.leftCols(0), 0, y, ws, packed),
                      Contains("samples 0 … -1"));
  REQUIRE_THROWS_WITH(net.forward_columns(random_matrix<double>(6, 4, 7, 1.0), 0, y, ws, packed),
                      Contains("X has 6 rows"));
}
