// Simulated labs for the tests: a world (written as YAML text or loaded from a file) synthesised
// into a suite in a scratch directory of this build tree.
#pragma once

#include <fstream>
#include <string>

#include "odomcov/io/suite_io.hpp"
#include "odomcov/io/world.hpp"
#include "test_util.hpp"

namespace odomcov::test {

/// Synthesises a world (every experiment, its seeds from the world's) and loads the suite back.
inline Suite synth_suite(const WorldFile& w, const std::string& tag) {
  const auto dir = scratch_dir("odomcov_synth_" + tag);
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    std::ofstream(dir / (w.experiments[i].name + ".csv")) << measurements_csv(synthesize(w, i), start_headings(w, i));
  }
  std::ofstream(dir / "suite.yaml") << suite_yaml(w);
  return load_suite((dir / "suite.yaml").string());
}

/// A world from its YAML text.
inline WorldFile world_from_text(const std::string& yaml, const std::string& tag) {
  const auto file = scratch_dir("odomcov_world_" + tag) / "world.yaml";
  std::ofstream(file) << yaml;
  return load_world(file.string());
}

}  // namespace odomcov::test
