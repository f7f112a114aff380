// The path config of ../shared/SPEC.md ("Path config"): robot, path, simulation settings.
#pragma once

#include <cstdint>
#include <string>

#include "odomcov/effects.hpp"
#include "odomcov/limits.hpp"
#include "odomcov/path.hpp"

namespace YAML {
class Node;
}

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

/// Reads and validates a path config. Throws InputError (file:line: key: what) on bad input.
Config load_config(const std::string& file);

/// Validates an already-parsed YAML tree (used by `sweep`, which edits keys before parsing).
Config parse_config(const YAML::Node& root, const std::string& file);

/// Parses the `path` block (sample_rate plus keyframes or segments), shared with measurement
/// suites. `key` is the block's dotted key path for messages.
Path parse_path(const YAML::Node& node, const std::string& file, const std::string& key,
                double wheelbase_m);

/// Parses an effect list (single-key maps, SPEC "Effect catalogue"); `key` for messages.
EffectList parse_effects(const YAML::Node& node, const std::string& file, const std::string& key);

/// Parses a `world` block {effects, k_left, k_right}; missing k's default to `nominal`.
World parse_world(const YAML::Node& node, const std::string& file, const std::string& key,
                  const WheelNoise& nominal);

/// Parses a `robot` block {wheelbase, k_left, k_right}.
Robot parse_robot(const YAML::Node& node, const std::string& file, const std::string& key);

/// Rejects a runs count outside [1, kMaxRuns] or a job above kMaxSimulationSteps.
void check_simulation_size(const std::string& file, int line, const std::string& key,
                           std::int64_t runs, std::int64_t samples_per_run);

}  // namespace odomcov
