// The simulator against the closed form, at stated alpha with fixed seeds; determinism across
// thread counts; the vectorised kernel against the scalar reference, bit for bit.
#include "odomcov/engine/simulator.hpp"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>

#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include "odomcov/engine/propagation.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

/// Level of every statistical assertion in this file.
constexpr double kAlpha = 1e-3;

Path segments_path(std::vector<PathSegment> segments, double wheelbase_m, double rate_hz) {
  return {rate_hz, keyframes_from_segments(segments, wheelbase_m, 0.5)};
}

/// Runs the simulation and applies the run tests (mean chi^2 and covariance LRT) plus an
/// element-wise check of the sample covariance: for Gaussian data
/// Var(s_ij) = (sigma_ii sigma_jj + sigma_ij^2)/(n - 1), and each of the 6 elements must lie
/// within z * SE with z the two-sided Bonferroni quantile at kAlpha.
void expect_matches_theory(const Robot& robot, const Path& path, std::int64_t runs,
                           std::uint64_t seed, const char* what) {
  const Matrix3 theory = path_covariance(path, robot).end().P_world;
  const Vector3 bias = noise_induced_mean(path, robot);
  ASSERT_LT(bias.dot(theory.llt().solve(bias)) * static_cast<double>(runs), 0.3 * 0.3)
      << what << ": first-order theory is not the right reference at this noise";
  const SampleMoments s = moments(Simulator(robot, path).simulate(runs, seed));
  const TestResult mean = mean_test_known_covariance(s, Vector3::Zero(), theory);
  const TestResult cov = covariance_test(s, theory);
  EXPECT_GE(mean.p_value, kAlpha) << what << ": mean " << s.mean.transpose();
  EXPECT_GE(cov.p_value, kAlpha) << what << ": covariance\n" << s.cov << "\nvs\n" << theory;
  const double z = boost::math::quantile(boost::math::normal(), 1.0 - kAlpha / (2 * 6));
  for (int i = 0; i < 3; ++i) {
    for (int j = i; j < 3; ++j) {
      const double se = std::sqrt((theory(i, i) * theory(j, j) + theory(i, j) * theory(i, j)) /
                                  static_cast<double>(runs - 1));
      EXPECT_NEAR(s.cov(i, j), theory(i, j), z * se) << what << " entry " << i << j;
    }
  }
}

TEST(Simulator, LineTurnAndArcMatchTheClosedForm) {
  // kL != kR, and small enough that the noise-induced (second-order) mean, which grows as k^2
  // while the standard error of the mean grows as k, stays below 0.3 standard errors here
  // (checked below with noise_induced_mean); at k ~ 1e-3 it is already 4 SE on a 3 m line.
  const Robot robot{0.5, {3e-5, 7.5e-5}};
  using K = PathSegment::Kind;
  expect_matches_theory(robot, segments_path({{K::line, 3.0, 0, 0}}, 0.5, 100), 20000, 11,
                        "line");
  expect_matches_theory(robot, segments_path({{K::line, -2.0, 0, 0}}, 0.5, 100), 20000, 12,
                        "backwards line");
  expect_matches_theory(robot, segments_path({{K::turn, 0, -3.0, 0}}, 0.5, 100), 20000, 13,
                        "clockwise turn");
  expect_matches_theory(robot, segments_path({{K::arc, 0, 2.0, 0.8}}, 0.5, 100), 20000, 14,
                        "left arc");
  expect_matches_theory(robot, segments_path({{K::arc, 0, 1.5, -0.6}}, 0.5, 100), 20000, 15,
                        "arc, negative radius, backwards");
  expect_matches_theory(robot,
                        segments_path({{K::line, 1.0, 0, 0},
                                       {K::arc, 0, -2.0, 0.4},
                                       {K::turn, 0, 1.0, 0},
                                       {K::line, -1.5, 0, 0}},
                                      0.5, 50),
                        20000, 16, "mixed path");
}

TEST(Simulator, TestsHavePowerAgainstAWrongModel) {
  // The same data against the theory with kL and kR swapped must be rejected: the tests above
  // can tell a wrong model apart at this sample size.
  using K = PathSegment::Kind;
  const Path path = segments_path({{K::arc, 0, 2.0, 0.8}, {K::line, 2.0, 0, 0}}, 0.5, 100);
  const SampleMoments s = moments(Simulator({0.5, {1e-3, 2.5e-3}}, path).simulate(20000, 21));
  const Matrix3 wrong = path_covariance(path, {0.5, {2.5e-3, 1e-3}}).end().P_world;
  EXPECT_LT(covariance_test(s, wrong).p_value, kAlpha);
}

TEST(Simulator, NoiseInducedMeanMatchesLargeNoise) {
  // Table V noise (kL = 0.01, kR = 0.02): first-order theory's zero mean is rejected, the
  // noise-induced mean is not (Hotelling's T^2 with the sample covariance, since at this noise
  // the covariance itself departs from first order).
  const Path fig7{200.0,
                  {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708},
                   {5, 3.37445, 4.15985}}};
  const Robot robot{0.5, {1e-2, 2e-2}};
  const SampleMoments s = moments(Simulator(robot, fig7).simulate(200000, 5));
  EXPECT_LT(hotelling_test(s, Vector3::Zero()).p_value, kAlpha);
  EXPECT_GE(hotelling_test(s, noise_induced_mean(fig7, robot)).p_value, kAlpha)
      << s.mean.transpose() << " vs " << noise_induced_mean(fig7, robot).transpose();
}

TEST(Simulator, ZeroNoiseGivesZeroError) {
  std::mt19937_64 rng(3);
  const test::RandomCase c = test::random_case(rng, 37.0);
  Robot silent = c.robot;
  silent.noise = {0.0, 0.0};
  const Simulator sim(silent, c.path);
  for (const Vector3& e : sim.errors(1, 0, 16)) EXPECT_EQ(e, Vector3::Zero());
}

TEST(Simulator, OdometryEndPoseIsTheNominalPath) {
  std::mt19937_64 rng(4);
  for (int trial = 0; trial < 20; ++trial) {
    test::RandomCase c = test::random_case(rng, 100.0);
    for (Keyframe& k : c.path.keyframes) k.t_s = std::ceil(k.t_s * 100.0) / 100.0;
    const Vector3 end = path_end_pose(c.path, c.robot.wheelbase_m);
    EXPECT_LT((Simulator(c.robot, c.path).odometry_end_pose() - end).norm(), 1e-10);
  }
}

TEST(Simulator, SameSeedSameBitsForAnyThreadCount) {
  const Path path{200.0, {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708}}};
  const Simulator sim({0.5, {1e-3, 2e-3}}, path);
  const MomentAccumulator one = sim.simulate(5003, 99, 1);
  for (int threads : {2, 3, 4}) {
    const MomentAccumulator many = sim.simulate(5003, 99, threads);
    EXPECT_EQ(many.count(), 5003);
    EXPECT_EQ(many.mean(), one.mean()) << threads << " threads";
    EXPECT_EQ(many.scatter(), one.scatter()) << threads << " threads";
  }
  EXPECT_NE(sim.simulate(5003, 100, 2).mean(), one.mean());  // the seed matters
  EXPECT_EQ(sim.errors(99, 10, 5, 1), sim.errors(99, 10, 5, 2));
}

// The stochastic effects draw from streams keyed by (run, sample, tag), never from a thread's
// state: per-run radii (one draw per run), bumps (a Poisson count and sizes per sample) and
// correlated wheel noise give the same bits on 1, 2, 3 and 4 threads.
TEST(Simulator, StochasticEffectsSameBitsForAnyThreadCount) {
  const Path path{50.0, {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708}}};
  const EffectList effects{{"per_run_radius", {0.003}},
                           {"bumps", {2.0, 0.004}},
                           {"wheel_noise_correlation", {0.4}}};
  const Simulator sim({0.5, {1e-3, 2e-3}}, path, effects);
  const MomentAccumulator one = sim.simulate(3001, 17, 1);
  for (int threads : {2, 3, 4}) {
    const MomentAccumulator many = sim.simulate(3001, 17, threads);
    EXPECT_EQ(many.count(), 3001);
    EXPECT_EQ(many.mean(), one.mean()) << threads << " threads";
    EXPECT_EQ(many.scatter(), one.scatter()) << threads << " threads";
  }
  // The effects do act: without them the moments differ.
  EXPECT_NE(Simulator({0.5, {1e-3, 2e-3}}, path).simulate(3001, 17, 1).scatter(), one.scatter());
  EXPECT_EQ(sim.errors(17, 100, 7, 1), sim.errors(17, 100, 7, 3));
}

/// Runs `body` once per SIMD target this build has and this CPU runs, that target selected;
/// the best target is selected again afterwards.
template <class F>
void for_each_kernel(F&& body) {
  for (const std::string& target : Simulator::kernel_targets()) {
    Simulator::select_kernel(target);
    SCOPED_TRACE("kernel " + target);
    body(target);
  }
  Simulator::select_kernel("");
}

// The stochastic effects run in the SIMD lanes too: every target, 1, 2 and 7 threads, with
// per-run draws (per_run_radius), per-sample draws (turn_slip), events (bumps), a noise mix
// (correlation) and a systematic effect folded into the legs.
TEST(Simulator, EveryKernelWithEffectsSameBitsFor1To7Threads) {
  const Path path{50.0, {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708}}};
  const EffectList effects{{"wheel_diameter_ratio", {1.004}}, {"turn_slip", {0.002}},
                           {"per_run_radius", {0.003}}, {"bumps", {2.0, 0.004}},
                           {"wheel_noise_correlation", {0.4}}};
  const Simulator sim({0.5, {1e-3, 2e-3}}, path, effects);
  Simulator::select_kernel("");
  const MomentAccumulator reference = sim.simulate(1003, 23, 1);
  const std::vector<Vector3> errors = sim.errors(23, 40, 77, 1);
  for_each_kernel([&](const std::string&) {
    for (int threads : {1, 2, 7}) {
      const MomentAccumulator m = sim.simulate(1003, 23, threads);
      EXPECT_EQ(m.count(), 1003);
      EXPECT_EQ(m.mean(), reference.mean()) << threads << " threads";
      EXPECT_EQ(m.scatter(), reference.scatter()) << threads << " threads";
      EXPECT_EQ(sim.errors(23, 40, 77, threads), errors) << threads << " threads";
    }
  });
}

// The seed -> numbers mapping (src/base/random.hpp, docs/performance.md) pinned: the bits of
// three runs without and with effects, the same on every instruction set and architecture (the
// aarch64 build checks them under qemu). Where they come from: the scalar reference of the
// stream with normals by inversion (4 words per Philox draw), printed when that stream was laid
// out (2026-12-02); every x86-64 target agreed with it bit for bit.
TEST(Simulator, SeedGivesTheDocumentedBits) {
  const Path path{50.0, {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708}}};
  const Robot robot{0.5, {1e-3, 2e-3}};
  const EffectList effects{{"wheel_diameter_ratio", {1.004}}, {"turn_slip", {0.002}},
                           {"per_run_radius", {0.003}}, {"bumps", {2.0, 0.004}},
                           {"wheel_noise_correlation", {0.4}}};
  const std::uint64_t expected[2][3][3] = {
      {{0x3f7f2ab1e49bb200ull, 0xbf883d143ed14f40ull, 0xbf8264662260e980ull},
       {0x3f3e87a7e5da4000ull, 0xbf81fdd928684780ull, 0x3f737a6d1474b1d0ull},
       {0xbf725701c6c8fe00ull, 0x3f3bc8fc21e27000ull, 0x3f7773de821e62d8ull}},
      {{0xbf406d6b6fac5000ull, 0xbf89a47bb0bffb40ull, 0xbf70462cb6792630ull},
       {0x3f9279e521507f00ull, 0xbfac2d8144a1bea0ull, 0xbfa106c926151a62ull},
       {0xbfabf7f5f85f90c0ull, 0x3fb6a5e3683b6890ull, 0x3fa56124cd0d6397ull}}};
  for_each_kernel([&](const std::string&) {
    for (int with : {0, 1}) {
      const Simulator sim(robot, path, with ? effects : EffectList{});
      const std::vector<Vector3> e = sim.errors(42, 1000, 3, 1);
      for (int r = 0; r < 3; ++r) {
        for (int i = 0; i < 3; ++i) {
          std::uint64_t bits;
          const double v = e[static_cast<std::size_t>(r)][i];
          std::memcpy(&bits, &v, sizeof bits);
          EXPECT_EQ(bits, expected[with][r][i]) << (with ? "effects" : "plain") << ", run " << r;
        }
        EXPECT_EQ(sim.reference_error(42, 1000 + r), e[static_cast<std::size_t>(r)]);
      }
    }
  });
}

TEST(Simulator, SelectKernelNamesOnlyCompiledTargets) {
  const std::vector<std::string> targets = Simulator::kernel_targets();
  ASSERT_FALSE(targets.empty());
  EXPECT_EQ(std::string(Simulator::kernel_isa()), targets.front());
  EXPECT_THROW(Simulator::select_kernel("no such target"), std::invalid_argument);
  Simulator::select_kernel(targets.back());
  EXPECT_EQ(std::string(Simulator::kernel_isa()), targets.back());
  Simulator::select_kernel("");
  EXPECT_EQ(std::string(Simulator::kernel_isa()), targets.front());
}

TEST(Simulator, VectorKernelMatchesScalarReferenceBitForBit) {
  // Includes lanes that leave the series bounds: large noise (|eps| > 0.05), a 2 Hz sample
  // rate on a fast spin (|h| > 0.45 per sample, division branch) and wheel reversals.
  // Every compiled target (x86-64: AVX-512, AVX2, SSE4 and the scalar fallback; aarch64: NEON),
  // plain and with every stochastic effect (odd trials), 37 runs: blocks of every width end
  // part-filled.
  // Trials 3, 7, 11 add a custom effect whose scale and lateral slip are drawn per run, so every
  // lane steps on its own legs (the kernel's per-lane leg table), their scales 20% apart (trial 3
  // on the 2 Hz spin).
  const EffectList effects{{"per_run_radius", {0.003}}, {"turn_slip", {0.01}},
                           {"bumps", {3.0, 0.004}}, {"wheel_noise_correlation", {-0.6}},
                           {"backlash", {0.002, 0.001}}};
  CustomEffect drawn;
  drawn.name = "drawn";
  drawn.parameters = {"c", "l"};
  drawn.scale.text = "1 + c";
  drawn.lateral.text = "l";
  drawn.random = {"c", "l"};
  EffectList with_drawn = effects;
  with_drawn.push_back(define_custom_effect(drawn, {0.0, 0.0, 0.2, 0.01}));
  for_each_kernel([&](const std::string&) {
    std::mt19937_64 rng(6);
    for (int trial = 0; trial < 12; ++trial) {
      test::RandomCase c = test::random_case(rng, trial % 3 == 0 ? 2.0 : 60.0);
      if (trial % 2 == 0) c.robot.noise = {0.15, 0.2};
      const EffectList& list = trial % 4 == 3 ? with_drawn : effects;
      const Simulator sim(c.robot, c.path, trial % 2 == 1 ? list : EffectList{});
      const std::vector<Vector3> fast = sim.errors(7, 1000, 37);
      for (std::int64_t r = 0; r < 37; ++r) {
        EXPECT_EQ(fast[static_cast<std::size_t>(r)], sim.reference_error(7, 1000 + r))
            << "trial " << trial << ", run " << r;
      }
    }
  });
}

// A logged run is simulated one sample per encoder piece: given the pieces of a path's own
// sample schedule (and their durations), it steps exactly as the path's simulation does, with
// and without stochastic and speed-dependent effects.
TEST(Simulator, LoggedPiecesStepAsThePathsSamples) {
  const Path path{50.0, {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4.01, 3.5708, 3.5708}}};
  std::vector<ArcSegment> pieces;
  std::vector<double> durations;
  for (const SampleRun& s : sample_schedule(path)) {
    for (std::int64_t i = 0; i < s.count; ++i) {
      pieces.push_back(s.increment);
      durations.push_back(s.duration_s);
    }
  }
  const Robot robot{0.5, {1e-3, 2e-3}};
  for (const EffectList& effects :
       {EffectList{}, EffectList{{"turn_slip", {0.002}}, {"per_run_radius", {0.003}}},
        EffectList{{"turn_dependent_wheelbase", {1.01, 0.98}}, {"bumps", {2.0, 0.004}}}}) {
    const Simulator by_path(robot, path, effects);
    const Simulator by_pieces(robot, pieces, durations, effects);
    EXPECT_EQ(by_pieces.samples_per_run(), by_path.samples_per_run());
    EXPECT_EQ(by_pieces.odometry_end_pose(), by_path.odometry_end_pose());
    EXPECT_EQ(by_pieces.errors(3, 0, 20, 1), by_path.errors(3, 0, 20, 1));
  }
  EXPECT_THROW(Simulator(robot, pieces, {1.0, 2.0}), std::invalid_argument);
}

TEST(Simulator, StreamingStatisticsMatchStoredErrors) {
  const Path path{100.0, {{0, 0, 0}, {1, 1.0, 1.2}, {2, 0.5, 2.0}}};
  const Simulator sim({0.4, {2e-3, 1e-3}}, path);
  const std::vector<Vector3> e = sim.errors(5, 0, 1001);
  const MomentAccumulator streamed = sim.simulate(1001, 5);
  const SampleMoments stored = moments(e);
  EXPECT_EQ(streamed.count(), 1001);
  EXPECT_LT((streamed.mean() - stored.mean).norm(), 1e-15);
  EXPECT_LT((streamed.covariance() - stored.cov).cwiseAbs().maxCoeff(), 1e-12 * stored.cov.norm());
}

TEST(Simulator, CancellationStopsEarly) {
  const Path path{100.0, {{0, 0, 0}, {10, 10, 10}}};
  const Simulator sim({0.5, {1e-3, 1e-3}}, path);
  Progress progress;
  progress.cancel = true;
  EXPECT_EQ(sim.simulate(100000, 1, 0, &progress).count(), 0);
  Progress counted;
  EXPECT_EQ(sim.simulate(1000, 1, 0, &counted).count(), 1000);
  EXPECT_EQ(counted.runs_done.load(), 1000);
}

}  // namespace
}  // namespace odomcov
