// The sign combination (TF semantics), its guarantees, and the combine → clip → step order.
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <vector>

#include "support/test_data.hpp"
#include "sbptt/core/error.hpp"
#include "sbptt/core/rng.hpp"
#include "sbptt/optim/adam.hpp"
#include "sbptt/optim/clip.hpp"
#include "sbptt/optim/combined_update.hpp"
#include "sbptt/optim/sgd.hpp"

namespace {

using sbptt::testing::vec;

using sbptt::ClipMode;
using sbptt::Index;
using sbptt::Vector;

template <class Scalar>
Vector<Scalar> random_vector(sbptt::Rng& rng, Index n) {
  Vector<Scalar> v(n);
  for (Index i = 0; i < n; ++i) {
    // Exact zeros are frequent in practice (stopped paths, masked components): include them.
    v(i) = rng.uniform() < 0.15 ? Scalar(0) : static_cast<Scalar>(rng.normal());
  }
  return v;
}

static_assert(sbptt::FlatOptimizer<sbptt::Adam<float>>);
static_assert(sbptt::FlatOptimizer<sbptt::Sgd<double>>);
static_assert(!sbptt::FlatOptimizer<int>);

}  // namespace

TEMPLATE_TEST_CASE("combine keeps g_M where the TF signs agree and 0 elsewhere",
                   "[optim][combine]", float, double) {
  using Scalar = TestType;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  //                                 agree  agree  disagr disagr both0 M=0  R=0  R=NaN M=NaN both NaN
  const Vector<Scalar> g_m = vec<Scalar>({1.0, -2.0, 3.0, -4.0, 0.0, 0.0, 5.0, 2.0, nan, nan, nan});
  const Vector<Scalar> g_r = vec<Scalar>({2.0, -1.0, -3.0, 4.0, 0.0, 1.0, 0.0, nan, 0.0, 1.0, nan});
  Vector<Scalar> out;
  sbptt::combine(g_m, g_r, out);
  const Vector<Scalar> expected =
      vec<Scalar>({1.0, -2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0});
  CHECK(out == expected);  // also false if any NaN slipped through
  // Agreeing components: the two same-sign ones and the both-zero one.
  CHECK(sbptt::sign_agreement(g_m, g_r) == Scalar(3) / Scalar(11));

  // The output may alias an input.
  Vector<Scalar> in_place = g_m;
  sbptt::combine(in_place, g_r, in_place);
  CHECK(in_place == expected);
  Vector<Scalar> in_place_r = g_r;
  sbptt::combine(g_m, in_place_r, in_place_r);
  CHECK(in_place_r == expected);

  CHECK_THROWS_WITH(sbptt::combine(vec<Scalar>({1.0, 2.0}), vec<Scalar>({1.0}), out),
                    Catch::Contains("g_R size = 1") && Catch::Contains("g_M size 2"));
  Vector<Scalar> empty;
  sbptt::combine(empty, empty, out);
  CHECK(out.size() == 0);
  CHECK(sbptt::sign_agreement(empty, empty) == Scalar(1));
}

TEMPLATE_TEST_CASE("combine reproduces the paper's toy-problem table", "[optim][combine]", float,
                   double) {
  using Scalar = TestType;
  Vector<Scalar> out;
  // docs/paper.md §3.1, θ = (2, −1): the vanishing regular gradient disagrees in the 2nd component.
  const Vector<Scalar> g_r1 = vec<Scalar>({-2.11568e-3, -2.05214e-2});
  const Vector<Scalar> g_m1 = vec<Scalar>({-0.253321, 0.0935972});
  sbptt::combine(g_m1, g_r1, out);
  CHECK(out == vec<Scalar>({-0.253321, 0.0}));
  // θ = (−3, −3).
  const Vector<Scalar> g_r2 = vec<Scalar>({-2.47227, -48.7552});
  const Vector<Scalar> g_m2 = vec<Scalar>({-5.79088, 5.3268});
  sbptt::combine(g_m2, g_r2, out);
  CHECK(out == vec<Scalar>({-5.79088, 0.0}));
  // θ = (1, 1): all signs agree, g_C = g_M.
  const Vector<Scalar> g_r3 = vec<Scalar>({-2.91843, 3.21987});
  const Vector<Scalar> g_m3 = vec<Scalar>({-5.44069, 7.52841});
  sbptt::combine(g_m3, g_r3, out);
  CHECK(out == g_m3);
}

TEMPLATE_TEST_CASE("combine: never an ascent direction, never larger than g_M",
                   "[optim][combine]", float, double) {
  using Scalar = TestType;
  sbptt::Rng rng(20240507);
  Vector<Scalar> out;
  int kept_some = 0, zeroed_some = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Index n = 1 + static_cast<Index>(rng.uniform() * 60.0);
    const Vector<Scalar> g_m = random_vector<Scalar>(rng, n);
    const Vector<Scalar> g_r = random_vector<Scalar>(rng, n);
    sbptt::combine(g_m, g_r, out);
    REQUIRE(out.size() == n);
    CHECK(out.dot(g_r) >= Scalar(0));
    Index kept = 0;
    for (Index i = 0; i < n; ++i) {
      CHECK(std::abs(out(i)) <= std::abs(g_m(i)));
      CHECK((out(i) == g_m(i) || out(i) == Scalar(0)));
      CHECK(out(i) * g_r(i) >= Scalar(0));
      const bool same = (g_m(i) > 0 && g_r(i) > 0) || (g_m(i) < 0 && g_r(i) < 0) ||
                        (g_m(i) == 0 && g_r(i) == 0);
      kept += same ? 1 : 0;
    }
    CHECK(sbptt::sign_agreement(g_m, g_r) == static_cast<Scalar>(kept) / static_cast<Scalar>(n));
    kept_some += (out.array() != 0).any() ? 1 : 0;
    zeroed_some += ((out.array() == 0) && (g_m.array() != 0)).any() ? 1 : 0;
  }
  // The property is not vacuous: both outcomes occur.
  CHECK(kept_some > 100);
  CHECK(zeroed_some > 100);
}

TEMPLATE_TEST_CASE("CombinedUpdate is combine, then clip, then the optimizer step",
                   "[optim][combine]", float, double) {
  using Scalar = TestType;
  sbptt::AdamOptions<Scalar> options;
  options.learning_rate = Scalar(0.01);
  const Scalar threshold = Scalar(0.5);

  const std::vector<Vector<Scalar>> g_m = {vec<Scalar>({3.0, -1.0, 0.5, 2.0}),
                                           vec<Scalar>({-1.0, 4.0, 0.0, 1.0}),
                                           vec<Scalar>({0.2, -0.2, 1.5, -3.0})};
  const std::vector<Vector<Scalar>> g_r = {vec<Scalar>({1.0, 2.0, 0.5, -1.0}),
                                           vec<Scalar>({-2.0, 1.0, 1.0, 1.0}),
                                           vec<Scalar>({0.1, 0.3, 2.0, -0.5})};

  sbptt::CombinedUpdate<sbptt::Adam<Scalar>> update(sbptt::Adam<Scalar>(options), ClipMode::Norm,
                                                    threshold);
  CHECK(update.clip_mode() == ClipMode::Norm);
  CHECK(update.clip_threshold() == threshold);
  Vector<Scalar> theta = vec<Scalar>({1.0, -1.0, 0.5, 0.0});

  // The same three operations by hand.
  sbptt::Adam<Scalar> manual_adam(options);
  Vector<Scalar> manual = theta;
  // The other order (clip g_M, then combine) as the counterfactual the test must tell apart.
  sbptt::Adam<Scalar> wrong_adam(options);
  Vector<Scalar> wrong = theta;

  for (std::size_t t = 0; t < g_m.size(); ++t) {
    update.step(theta, g_m[t], g_r[t]);

    Vector<Scalar> g_c;
    sbptt::combine(g_m[t], g_r[t], g_c);
    const Scalar expected_norm2 = g_c.squaredNorm();
    const Scalar expected_agreement = sbptt::sign_agreement(g_m[t], g_r[t]);
    sbptt::clip(g_c, ClipMode::Norm, threshold);
    manual_adam.step(manual, g_c);

    Vector<Scalar> clipped_first = g_m[t];
    sbptt::clip(clipped_first, ClipMode::Norm, threshold);
    Vector<Scalar> g_w;
    sbptt::combine(clipped_first, g_r[t], g_w);
    wrong_adam.step(wrong, g_w);

    CHECK(theta == manual);
    CHECK(static_cast<double>(update.last_norm2()) ==
          Approx(static_cast<double>(expected_norm2)).epsilon(1e-5));
    CHECK(update.last_agreement() == expected_agreement);
  }
  CHECK(update.inner().iterations() == 3);
  CHECK((theta - wrong).cwiseAbs().maxCoeff() > Scalar(1e-4));
  // Step 3 by hand: g_C = (0.2, 0, 1.5, −3), so ‖g_C‖² = 11.29 and 3 of 4 signs agree.
  CHECK(static_cast<double>(update.last_norm2()) == Approx(11.29).epsilon(1e-5));
  CHECK(update.last_agreement() == Scalar(0.75));
}

TEST_CASE("the logged squared norm of a float update does not overflow where the norm is finite",
          "[optim][combine]") {
  // ‖g‖ = 1e20 is a finite float and clipping rescales g correctly (stableNorm); its square,
  // 1e40, is beyond float's range. A quantum-control run at the published budget logged "inf"
  // here, and a checkpoint holding that row could not be read back.
  sbptt::ClippedUpdate<sbptt::Sgd<float>> update(sbptt::Sgd<float>(sbptt::SgdOptions<float>{}),
                                                 ClipMode::Norm, 1.0F);
  Vector<float> theta = vec<float>({0.0, 0.0});
  update.step(theta, vec<float>({6e19, 8e19}));
  CHECK(std::isfinite(update.last_norm2()));
  CHECK(update.last_norm2() == Approx(1e40).epsilon(1e-6));
  CHECK(theta.allFinite());
}

TEMPLATE_TEST_CASE("ClippedUpdate clips a copy and steps; the caller's gradient is untouched",
                   "[optim][combine]", float, double) {
  using Scalar = TestType;
  sbptt::SgdOptions<Scalar> options;
  options.learning_rate = Scalar(0.5);
  sbptt::ClippedUpdate<sbptt::Sgd<Scalar>> update(sbptt::Sgd<Scalar>(options), ClipMode::Value,
                                                  Scalar(1));
  Vector<Scalar> theta = vec<Scalar>({0.0, 0.0, 0.0});
  const Vector<Scalar> grad = vec<Scalar>({3.0, -0.5, -2.0});
  update.step(theta, grad);
  CHECK(grad == vec<Scalar>({3.0, -0.5, -2.0}));
  CHECK(theta == vec<Scalar>({-0.5, 0.25, 0.5}));
  CHECK(static_cast<double>(update.last_norm2()) == Approx(13.25).epsilon(1e-6));

  // Sgd inside CombinedUpdate: g_C = (3, 0, −2) clipped to (1, 0, −1).
  sbptt::CombinedUpdate<sbptt::Sgd<Scalar>> combined(sbptt::Sgd<Scalar>(options), ClipMode::Value,
                                                     Scalar(1));
  Vector<Scalar> phi = vec<Scalar>({0.0, 0.0, 0.0});
  combined.step(phi, grad, vec<Scalar>({1.0, 1.0, -1.0}));
  CHECK(phi == vec<Scalar>({-0.5, 0.0, 0.5}));

  using Wrapped = sbptt::ClippedUpdate<sbptt::Sgd<Scalar>>;
  using Combined = sbptt::CombinedUpdate<sbptt::Adam<Scalar>>;
  CHECK_THROWS_WITH(Wrapped(sbptt::Sgd<Scalar>(), ClipMode::Norm, Scalar(0)),
                    Catch::Contains("clip threshold = 0"));
  CHECK_THROWS_AS(Combined(sbptt::Adam<Scalar>(), ClipMode::Value, Scalar(-1)),
                  sbptt::InvalidArgument);
  CHECK_NOTHROW(Combined(sbptt::Adam<Scalar>(), ClipMode::None, Scalar(0)));
  Combined sized;
  Vector<Scalar> two = vec<Scalar>({1.0, 2.0});
  CHECK_THROWS_AS(sized.step(two, vec<Scalar>({1.0, 2.0}), vec<Scalar>({1.0})),
                  sbptt::InvalidArgument);
}

TEMPLATE_TEST_CASE("CombinedUpdate: a fixed gradient sequence gives bitwise-identical parameters",
                   "[optim][combine]", float, double) {
  using Scalar = TestType;
  auto run = [] {
    sbptt::Rng rng(7);
    sbptt::CombinedUpdate<sbptt::Adam<Scalar>> update(sbptt::Adam<Scalar>(), ClipMode::Norm,
                                                      Scalar(1));
    Vector<Scalar> theta = Vector<Scalar>::Zero(101);
    for (int t = 0; t < 40; ++t) {
      const Vector<Scalar> g_m = random_vector<Scalar>(rng, theta.size());
      const Vector<Scalar> g_r = random_vector<Scalar>(rng, theta.size());
      update.step(theta, g_m, g_r);
    }
    return theta;
  };
  const Vector<Scalar> first = run();
  CHECK(first == run());
  CHECK(first.cwiseAbs().maxCoeff() > Scalar(0));
}

TEMPLATE_TEST_CASE("CombinedUpdate::step_combined with g_C formed beforehand is step",
                   "[optim][combine]", float, double) {
  // The engine forms g_C in the pass that compares g_M with g_R; stepping with it must leave
  // the parameters, the optimizer and the logged figures exactly as `step` from g_M and g_R.
  using Scalar = TestType;
  using Update = sbptt::CombinedUpdate<sbptt::Adam<Scalar>>;
  sbptt::Rng rng(5);
  Update from_pair(sbptt::Adam<Scalar>(), ClipMode::Norm, Scalar(1));
  Update from_combined(sbptt::Adam<Scalar>(), ClipMode::Norm, Scalar(1));
  Vector<Scalar> theta = Vector<Scalar>::Zero(57), theta_combined = theta, g_c;
  for (int t = 0; t < 20; ++t) {
    const Vector<Scalar> g_m = random_vector<Scalar>(rng, theta.size());
    const Vector<Scalar> g_r = random_vector<Scalar>(rng, theta.size());
    from_pair.step(theta, g_m, g_r);
    sbptt::combine(g_m, g_r, g_c);
    from_combined.step_combined(theta_combined, g_c, sbptt::sign_agreement(g_m, g_r));
    INFO("step " << t);
    CHECK(theta_combined == theta);
    CHECK(from_combined.last_norm2() == from_pair.last_norm2());
    CHECK(from_combined.last_agreement() == from_pair.last_agreement());
  }
  CHECK(from_combined.inner().iterations() == 20);
  CHECK(theta.cwiseAbs().maxCoeff() > Scalar(0));
  CHECK_THROWS_WITH(from_combined.step_combined(theta_combined, g_c, Scalar(1.5)),
                    Catch::Contains("agreement = 1.5; expected a fraction in [0, 1]"));
  CHECK(from_combined.inner().iterations() == 20);
}

TEMPLATE_TEST_CASE("a step the update wrappers refuse changes nothing, and they name themselves",
                   "[optim][combine]", float, double) {
  // Refused for its sizes, a step left the logged norm and agreement of the vector it had
  // already combined and clipped, and the message named Adam::step. Then every later step
  // must be that of a run that never saw the refused one.
  using Scalar = TestType;
  using Combined = sbptt::CombinedUpdate<sbptt::Adam<Scalar>>;
  using Clipped = sbptt::ClippedUpdate<sbptt::Adam<Scalar>>;
  const Vector<Scalar> g_m = vec<Scalar>({3.0, -0.5, -2.0, 1.0});
  const Vector<Scalar> g_r = vec<Scalar>({1.0, 1.0, -1.0, 1.0});
  const Vector<Scalar> short_m = vec<Scalar>({9.0, 9.0, 9.0});
  Combined refused(sbptt::Adam<Scalar>(), ClipMode::Norm, Scalar(1));
  Combined reference(sbptt::Adam<Scalar>(), ClipMode::Norm, Scalar(1));
  Clipped refused_clipped(sbptt::Adam<Scalar>(), ClipMode::Norm, Scalar(1));
  Clipped reference_clipped(sbptt::Adam<Scalar>(), ClipMode::Norm, Scalar(1));
  Vector<Scalar> theta = Vector<Scalar>::Zero(4), theta_ref = theta;
  Vector<Scalar> phi = Vector<Scalar>::Zero(4), phi_ref = phi;
  refused.step(theta, g_m, g_r);
  reference.step(theta_ref, g_m, g_r);
  refused_clipped.step(phi, g_m);
  reference_clipped.step(phi_ref, g_m);
  const double norm2 = refused.last_norm2();
  const Scalar agreement = refused.last_agreement();

  CHECK_THROWS_WITH(refused.step(theta, short_m, short_m),
                    Catch::Contains("CombinedUpdate::step: gradient size = 3, expected the "
                                    "parameter size 4"));
  CHECK_THROWS_WITH(refused.step(theta, g_m, short_m),
                    Catch::StartsWith("CombinedUpdate::step: ") && Catch::Contains("3"));
  Vector<Scalar> short_c = short_m;
  CHECK_THROWS_WITH(refused.step_combined(theta, short_c, Scalar(0)),
                    Catch::Contains("CombinedUpdate::step_combined: gradient size = 3"));
  CHECK(short_c == short_m);
  Vector<Scalar> longer = Vector<Scalar>::Zero(5), long_c = Vector<Scalar>::Ones(5);
  // Sizes that agree, but not with Adam's state: Adam's own check refuses it.
  CHECK_THROWS_WITH(refused.step_combined(longer, long_c, Scalar(0)),
                    Catch::Contains("Adam::step: parameter size = 5"));
  CHECK(static_cast<double>(long_c.norm()) == Approx(1.0));  // clipped, as documented
  CHECK(refused.last_norm2() == norm2);
  CHECK(refused.last_agreement() == agreement);
  CHECK_THROWS_WITH(refused_clipped.step(phi, short_m),
                    Catch::Contains("ClippedUpdate::step: gradient size = 3, expected the "
                                    "parameter size 4"));
  CHECK(refused_clipped.last_norm2() == reference_clipped.last_norm2());

  refused.step(theta, g_r, g_m);
  reference.step(theta_ref, g_r, g_m);
  refused_clipped.step(phi, g_r);
  reference_clipped.step(phi_ref, g_r);
  CHECK(theta == theta_ref);
  CHECK(phi == phi_ref);
  CHECK(refused.inner().iterations() == 2);
}
