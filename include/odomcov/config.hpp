// The path config (docs/formats.md, "Path config"): robot, path, simulation settings.
#pragma once

#include <cstdint>
#include <string>

#include "odomcov/effects.hpp"
#include "odomcov/limits.hpp"
#include "odomcov/path.hpp"

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

/// Reads a YAML file that is a list of effects, catalogue or custom (diagnose --candidates).
/// Throws InputError (file:line: key: what) on bad input.
EffectList load_effects(const std::string& file);
/// The same from YAML text (or JSON, which is YAML): the Python module's `effects=`, so every
/// front door reads effects with one parser. `source` names the text in errors, as its
/// file and as the list's key ("effects:1: effects[0].custom.name: ...").
EffectList parse_effect_list(const std::string& text, const std::string& source);

/// Rejects a runs count outside [1, kMaxRuns] or a job above kMaxSimulationSteps.
void check_simulation_size(const std::string& file, int line, const std::string& key,
                           std::int64_t runs, std::int64_t samples_per_run);

}  // namespace odomcov
