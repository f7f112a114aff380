// synth writes a suite that loads back exactly, holds no trace of the world's effects, and is
// deterministic.
#include "odomcov/io/world.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "odomcov/engine/simulator.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_io.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

const std::string kWorld = ODOMCOV_SOURCE_DIR "/tests/data/worlds/small.yaml";

std::string write_suite(const WorldFile& w, const std::string& name) {
  const auto dir = test::scratch_dir(name);
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    std::ofstream(dir / (w.experiments[i].name + ".csv")) << measurements_csv(synthesize(w, i));
  }
  std::ofstream(dir / "suite.yaml") << suite_yaml(w);
  return (dir / "suite.yaml").string();
}

TEST(Synth, SuiteLoadsBackExactly) {
  const WorldFile w = load_world(kWorld);
  ASSERT_EQ(w.world.noise.k_left, 1.5e-3);   // the world's own noise
  ASSERT_EQ(w.world.noise.k_right, 1.2e-3);  // defaults to the robot's
  const Suite suite = load_suite(write_suite(w, "odomcov_synth_roundtrip"));
  EXPECT_EQ(suite.name, "small-lab");
  EXPECT_EQ(suite.robot.wheelbase_m, 0.4);
  EXPECT_EQ(suite.robot.noise.k_left, 1.0e-3);  // the nominal robot, not the world's
  EXPECT_TRUE(suite.model_effects.empty());
  EXPECT_NEAR(suite.measurement_noise.xy_m, 0.002, 1e-18);
  EXPECT_NEAR(suite.measurement_noise.theta_rad, 0.1 * M_PI / 180, 1e-18);
  ASSERT_EQ(suite.experiments.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const SuiteExperiment& ex = suite.experiments[i];
    EXPECT_EQ(ex.name, w.experiments[i].name);
    EXPECT_EQ(ex.path.keyframes.size(), w.experiments[i].path.keyframes.size());
    const std::vector<Vector3> measured = synthesize(w, i);
    ASSERT_EQ(ex.runs.size(), measured.size());
    const Simulator sim({0.4, w.world.noise}, w.experiments[i].path, w.world.effects);
    for (std::size_t r = 0; r < measured.size(); ++r) {
      EXPECT_EQ(ex.runs[r].id, std::to_string(r + 1));
      EXPECT_EQ(ex.runs[r].measured, measured[r]);  // %.17g round-trips
      EXPECT_LT((odometry_end_pose(ex, ex.runs[r], 0.4) - sim.odometry_end_pose()).norm(), 1e-12);
    }
  }
}

TEST(Synth, SuiteHoldsNoTraceOfTheWorld) {
  const std::string text = suite_yaml(load_world(kWorld));
  for (const char* secret : {"effects", "wheel_diameter_ratio", "per_run_radius", "world", "0.0015"}) {
    EXPECT_EQ(text.find(secret), std::string::npos) << secret;
  }
}

TEST(Synth, DeterministicAndSeeded) {
  const WorldFile w = load_world(kWorld);
  EXPECT_EQ(synthesize(w, 0, 1), synthesize(w, 0, 2));
  WorldFile other = w;
  other.seed = 6;
  EXPECT_NE(synthesize(other, 0), synthesize(w, 0));
  EXPECT_NE(synthesize(w, 0)[0], synthesize(w, 1)[0]);  // experiments get their own seeds
}

}  // namespace
}  // namespace odomcov
