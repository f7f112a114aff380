// Labs for the tests: a world (written as YAML text or loaded from a file) synthesised into a
// suite in a scratch directory of this build tree, or the real OptiOdom recordings of
// data/optiodom imported there.
#pragma once

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "odomcov/io/optiodom.hpp"
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

/// Every session of the given OptiOdom path types ("square", "ivanjko", "circular", "free") in
/// data/optiodom, imported as `odomcov import optiodom data/optiodom/data/diff/TYPE/* ...
/// --wheelbase 0.2 --diameters 0.084,0.084` would (the session as the group).
inline Suite optiodom_suite(const std::vector<std::string>& types, const std::string& tag) {
  OptiOdomOptions o;
  for (const std::string& type : types) {
    for (const auto& session : std::filesystem::directory_iterator(ODOMCOV_SOURCE_DIR "/data/optiodom/data/diff/" + type)) {
      if (session.is_directory()) o.sessions.push_back(session.path().string());
    }
  }
  std::sort(o.sessions.begin(), o.sessions.end());
  o.wheelbase_m = 0.2;
  o.diameters_m = {{0.084, 0.084}};
  const auto dir = scratch_dir("odomcov_optiodom_" + tag);
  for (const ImportedFile& f : import_optiodom(o)) {
    std::filesystem::create_directories((dir / f.path).parent_path());
    std::ofstream(dir / f.path) << f.text;
  }
  return load_suite((dir / "suite.yaml").string());
}

}  // namespace odomcov::test
