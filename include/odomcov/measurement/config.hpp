// The path config (docs/formats.md, "Path config"): robot, path, simulation settings. Reading it
// from YAML is io/config_io.hpp.
#pragma once

#include <cstdint>
#include <string>

#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/closed_form/path.hpp"

namespace odomcov {

struct SimulationSettings {
  std::int64_t runs = 10'000;
  std::uint64_t seed = 1;
};

/// The simulated world: its effects and, optionally, true wheel noise constants that differ
/// from the nominal robot's (the `world` block).
struct World {
  EffectList effects;
  WheelNoise noise;  // defaults to the robot's
};

struct Config {
  std::string file;  // where it was read from, for messages
  std::string name;  // defaults to the file's stem
  Robot robot;       // the nominal robot, which the model and the odometry use
  Path path;
  World world;
  EffectList model_effects;  // defaults to world.effects
  SimulationSettings simulation;

  /// The robot as the world has it: nominal wheelbase, the world's wheel noise.
  Robot world_robot() const { return {robot.wheelbase_m, world.noise}; }
};

}  // namespace odomcov
