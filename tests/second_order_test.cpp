// The order-2 model (second_order.hpp): an analytic golden case at large noise, the limit to
// the first-order engine as the noise goes to 0 (every catalogue effect), split invariance,
// and the coarsened route for logged runs.
#include "odomcov/engine/second_order.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "test_util.hpp"

namespace odomcov {
namespace {

using test::max_rel_diff;

/// Every catalogue effect at a moderate size (model side).
EffectList all_effects() {
  return {{"wheel_diameter_ratio", {1.004}}, {"wheelbase_error", {1.01}},
          {"scale_error", {0.995}},          {"wheel_noise_correlation", {0.3}},
          {"turn_slip", {0.002}},            {"per_run_radius", {0.0005}},
          {"bumps", {2.0, 0.001}}};
}

std::vector<ArcSegment> mixed_pieces(double B) {
  const std::vector<PathSegment> segments = [] {
    std::vector<PathSegment> s(5);
    s[0].kind = PathSegment::Kind::line, s[0].distance_m = 3.0;
    s[1].kind = PathSegment::Kind::turn, s[1].angle_rad = M_PI / 2;
    s[2].kind = PathSegment::Kind::arc, s[2].radius_m = 1.0, s[2].angle_rad = 2.0;
    s[3].kind = PathSegment::Kind::line, s[3].distance_m = -1.5;
    s[4].kind = PathSegment::Kind::arc, s[4].radius_m = -0.8, s[4].angle_rad = -1.5;
    return s;
  }();
  const Path path{50.0, keyframes_from_segments(segments, B, 0.5)};
  return model_pieces(path, B);
}

// Golden values: a straight line of length L with kL = kR = k (so I_td = 0), derived by hand
// (docs/orders.md, "A check in closed form"). The heading error is Brownian, Var phi(s) = q s
// with q = 2 k^2 / B^2, and the along-track noise has intensity k^2/2 per metre. With c = q/2,
//   E[x] - L = (1 - e^{-cL})/c - L,
//   I1 = int int e^{-c|t-s|} = 2 (L/c - (1 - e^{-cL})/c^2),
//   I2 = int int e^{-c(s+t+2 min)} = (2/(3c)) ((1 - e^{-cL})/c - (1 - e^{-4cL})/(4c)),
//   Var x = (I1 + I2)/2 - M^2 + (k^2/4) (L + (1 - e^{-2qL})/(2q)),  M = (1 - e^{-cL})/c,
//   Var y = (I1 - I2)/2 + (k^2/4) (L - (1 - e^{-2qL})/(2q)),
//   Cov(y, theta) = q ((1 - e^{-cL})/c^2 - L e^{-cL}/c),  Cov(x, theta) = Cov(x, y) = 0.
TEST(SecondOrder, LineMatchesClosedFormAtLargeNoise) {
  const double B = 0.5, k = 0.05, L = 20.0;  // Var theta_end = 0.4 rad^2: far from first order
  const Robot robot{B, {k, k}};
  const double q = 2 * k * k / (B * B), c = q / 2;
  const double M = (1 - std::exp(-c * L)) / c;
  const double i1 = 2 * (L / c - (1 - std::exp(-c * L)) / (c * c));
  const double i2 = 2 / (3 * c) * ((1 - std::exp(-c * L)) / c - (1 - std::exp(-4 * c * L)) / (4 * c));
  const double dn = k * k / 4 * (1 - std::exp(-2 * q * L)) / (2 * q);
  Matrix3 expected = Matrix3::Zero();
  expected(0, 0) = (i1 + i2) / 2 - M * M + k * k / 4 * L + dn;
  expected(1, 1) = (i1 - i2) / 2 + k * k / 4 * L - dn;
  expected(1, 2) = expected(2, 1) = q * ((1 - std::exp(-c * L)) / (c * c) - L * std::exp(-c * L) / c);
  expected(2, 2) = q * L;
  const Prediction p = predict_second_order({{L, L}}, robot, {});
  EXPECT_LT(max_rel_diff(p.cov, expected), 1e-9) << p.cov << "\n\n" << expected;
  EXPECT_NEAR(p.noise_mean.x(), M - L, 1e-9 * L);
  EXPECT_NEAR(p.noise_mean.y(), 0.0, 1e-12);
  // First order is far off here (the point of order 2): Var y differs by more than 10%.
  const Prediction p1 = predict({{L, L}}, robot, {});
  EXPECT_GT(std::abs(p1.cov(1, 1) / expected(1, 1) - 1), 0.1);
}

// As the noise goes to 0 the order-2 covariance tends to the first-order engine's, with a
// relative difference O(noise^2): at noise scale eps the difference must fall ~100x when eps
// falls 10x, for every catalogue effect (including per-run constants and bumps' equivalent).
TEST(SecondOrder, ReducesToFirstOrderAsNoiseVanishes) {
  const double B = 0.4;
  const auto pieces = mixed_pieces(B);
  EffectList effects = all_effects();
  double previous = 0.0;
  for (double eps : {1.0, 0.1, 0.01}) {
    const Robot robot{B, {2e-3 * eps, 3e-3 * eps}};
    EffectList scaled = effects;
    scaled[3].values = {0.3};
    scaled[4].values = {0.02 * eps};         // turn slip k
    scaled[5].values = {0.004 * eps};        // per-run radius sigma
    scaled[6].values = {2.0, 0.01 * eps};    // bumps sigma
    const Prediction p1 = predict(pieces, robot, scaled);
    const Prediction p2 = predict_second_order(pieces, robot, scaled);
    const double diff = max_rel_diff(p2.cov, p1.cov);
    EXPECT_LT((p2.mean - p1.mean).norm(), 1e-12);  // the same exact systematic path
    // The noise-induced mean agrees with the first-order engine's to leading order.
    EXPECT_LT((p2.noise_mean - p1.noise_mean).norm(), 0.05 * p1.noise_mean.norm() + 1e-18);
    if (previous > 0.0) EXPECT_LT(diff, previous / 50) << "eps " << eps;
    previous = diff;
  }
}

// Split invariance: cutting every piece into 3 gives the same prediction (the quadrature then
// has 3x the nodes, so this also bounds its error).
TEST(SecondOrder, SplitInvariant) {
  std::mt19937_64 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const test::RandomCase c = test::random_case(rng);
    const auto pieces = model_pieces(c.path, c.robot.wheelbase_m);
    std::vector<ArcSegment> split;
    for (const ArcSegment& s : pieces) {
      for (int i = 0; i < 3; ++i) split.push_back({s.left_m / 3, s.right_m / 3});
    }
    const EffectList effects = trial % 2 ? all_effects() : EffectList{};
    const Prediction a = predict_second_order(pieces, c.robot, effects);
    const Prediction b = predict_second_order(split, c.robot, effects);
    EXPECT_LT(max_rel_diff(b.cov, a.cov), 1e-9) << "trial " << trial;
    EXPECT_LT((b.noise_mean - a.noise_mean).norm(), 1e-9 * a.noise_mean.norm() + 1e-15);
    EXPECT_LT((b.mean - a.mean).norm(), 1e-12);
  }
}

// A logged run (one piece per sample) goes through coarsened pieces for the higher-order
// correction; against the order-2 model on the exact keyframe pieces the difference is a small
// fraction of the order-2 correction itself.
TEST(SecondOrder, CoarsenedLogMatchesPlannedPath) {
  const double B = 0.4;
  const Robot robot{B, {2e-2, 3e-2}};
  const auto planned = mixed_pieces(B);
  std::vector<ArcSegment> samples;  // 100 samples per planned piece
  for (const ArcSegment& s : planned) {
    for (int i = 0; i < 100; ++i) samples.push_back({s.left_m / 100, s.right_m / 100});
  }
  const auto coarse = coarsen_pieces(samples, B);
  EXPECT_LT(coarse.size(), samples.size() / 50);
  for (const ArcSegment& s : coarse) {
    EXPECT_LE(std::abs(s.heading_change_rad(B)), kPieceMaxAngle + 1e-12);
    EXPECT_LE(std::abs(s.center_m()), kPieceMaxTravel + 1e-12);
  }
  const EffectList effects = all_effects();
  const Prediction exact = predict_second_order(planned, robot, effects);
  const Prediction logged = predict_with_order(samples, robot, effects, 2);
  const Prediction first = predict(samples, robot, effects);
  // The coarse pieces merge across planned pieces, so only the correction is approximated:
  // its error must stay below 2% of the correction.
  const double correction = (exact.cov - first.cov).cwiseAbs().maxCoeff();
  EXPECT_GT(correction, 1e-3 * exact.cov.cwiseAbs().maxCoeff());  // the correction matters here
  EXPECT_LT((logged.cov - exact.cov).cwiseAbs().maxCoeff(), 0.02 * correction);
  EXPECT_LT((logged.mean + logged.noise_mean - exact.mean - exact.noise_mean).norm(),
            0.02 * exact.noise_mean.norm());
}

}  // namespace
}  // namespace odomcov
