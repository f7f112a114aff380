// Library-level config parsing; the bad-input contract (exit code 2, one line, no output) is
// tested through the CLI in CMakeLists.txt.
#include "odomcov/measurement/config.hpp"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "odomcov/base/error.hpp"
#include "odomcov/io/config_io.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

std::string write_temp(const std::string& text) {
  static int count = 0;
  static const std::filesystem::path dir = test::scratch_dir("odomcov_config");
  const std::string name = (dir / ("config-" + std::to_string(++count) + ".yaml")).string();
  std::ofstream(name) << text;
  return name;
}

TEST(Config, SegmentsExpandToKeyframes) {
  const std::string file = write_temp(R"(
robot: {wheelbase: 0.4, k_left: 1e-3, k_right: 2e-3}
path:
  sample_rate: 50
  speed: 0.25
  segments:
    - line: -1.0
    - turn_deg: -90
    - arc: {radius: -0.5, angle_deg: 45}
)");
  const Config c = load_config(file);
  EXPECT_EQ(c.name, std::filesystem::path(file).stem().string());
  EXPECT_EQ(c.simulation.runs, 10000);  // defaults
  EXPECT_EQ(c.simulation.seed, 1u);
  ASSERT_EQ(c.path.keyframes.size(), 4u);
  EXPECT_DOUBLE_EQ(c.path.keyframes[1].t_s, 4.0);
  EXPECT_DOUBLE_EQ(c.path.keyframes[1].left_m, -1.0);
  EXPECT_DOUBLE_EQ(c.path.interval(1).left_m, 0.2 * M_PI / 2);  // CW turn: left forwards
  EXPECT_DOUBLE_EQ(c.path.interval(2).heading_change_rad(0.4), M_PI / 4);
  EXPECT_LT(c.path.interval(2).center_m(), 0.0);  // R a < 0: backwards
  std::remove(file.c_str());
}

TEST(Config, ErrorsCarryFileLineAndKey) {
  const std::string file = write_temp(R"(robot:
  wheelbase: 0.5
  k_left: 1e-3
  k_right: 1e-3
path:
  sample_rate: 10
  keyframes: [[0, 0, 0], [1, 1, 1], [1, 2, 2]]
)");
  try {
    load_config(file);
    FAIL() << "expected an InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), file);
    EXPECT_EQ(e.line(), 7);
    EXPECT_EQ(e.key(), "path.keyframes[2]");
  }
  std::remove(file.c_str());
}

TEST(Config, RejectsAbsurdJobs) {
  const std::string file = write_temp(R"(robot: {wheelbase: 0.5, k_left: 1e-3, k_right: 1e-3}
path: {sample_rate: 1e7, keyframes: [[0, 0, 0], [100, 1, 1]]}
)");
  EXPECT_THROW(load_config(file), InputError);  // 1e9 samples per run > 1e8
  std::remove(file.c_str());
  EXPECT_THROW(check_simulation_size("f", 1, "runs", 1'000'000, 10'000'000), InputError);
  EXPECT_NO_THROW(check_simulation_size("f", 1, "runs", 10'000'000, 1000));
}

}  // namespace
}  // namespace odomcov
