// World files and `synth`: a simulated lab. A world file names the nominal robot, the world's
// hidden effects (and, optionally, its true wheel noise), the measurement noise of the external
// reference and a list of experiments; synth drives them and writes the measurement suite a
// lab would have, with no trace of the hidden effects.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "odomcov/measurement/config.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_writer.hpp"

namespace odomcov {

/// Where a world experiment's runs start, in the reference's own frame (`heading0:`): a fixed
/// heading [rad], or each run's drawn uniformly from [lo, hi] (`heading0: {uniform: [lo, hi]}`).
struct StartHeading {
  bool given = false;  // else every run starts at 0 and the CSV has no heading0 column
  double lo = 0.0, hi = 0.0;  // lo == hi: fixed
};

struct WorldExperiment {
  std::string name;
  std::int64_t runs = 0;
  Path path;
  std::string path_yaml;  // the path block as written (YAML text), to copy into the suite
  std::string group;      // `group:`, copied into the suite; empty: a group of its own
  std::string kind;       // `kind:`, copied into the suite; empty: the name's default
  StartHeading heading0;
  int line = 0;           // of the experiment in the world file, for messages
};

struct WorldFile {
  std::string file;
  std::string name;
  Robot robot;  // the nominal robot: the suite's model
  World world;  // the truth
  MeasurementNoise measurement_noise;
  std::uint64_t seed = 1;
  std::vector<WorldExperiment> experiments;
};

/// Reads and validates a world file (errors name file, line and key).
WorldFile load_world(const std::string& file);

/// The measured end poses (start frame) of experiment i: odometry end pose + simulated error,
/// plus measurement noise. Experiment i uses a seed derived from (seed, i); a group_variation
/// is drawn per group from the world's seed and the group (group_effects), so the experiments
/// of one group share it. Each run starts at its start_headings value: when the world's effects
/// use the absolute heading and the runs' start headings differ, each run is simulated on its
/// own (the same numbers as in one batch, run by run). Throws InputError (the world file, the
/// experiment's line and key) when a run ends beyond the suite loader's limits (limits.hpp):
/// the world's effects are then absurdly large, and the suite written would not load.
std::vector<Vector3> synthesize(const WorldFile& world, std::size_t experiment, int threads = 0);

/// Each run's start heading in the reference's frame for experiment i (`heading0:`), empty when
/// the experiment gives none: drawn at (seed derived from (seed, i), run, kTagStartHeading).
std::vector<double> start_headings(const WorldFile& world, std::size_t experiment);

/// The suite document of the synthesised data (see suite_writer.hpp), and its text.
SuiteDocument world_suite(const WorldFile& world);
/// The suite.yaml text for the synthesised data: nominal robot, measurement noise and the
/// experiments with their paths and CSV names (<name>.csv).
std::string suite_yaml(const WorldFile& world);

/// The measurements CSV (run,x,y,theta) of one experiment; with each run's start heading
/// (start_headings, when not empty) in a fifth column, heading0.
std::string measurements_csv(const std::vector<Vector3>& measured, const std::vector<double>& heading0 = {});

}  // namespace odomcov
