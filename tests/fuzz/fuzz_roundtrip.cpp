// Fuzz target, round trip: a world file is synthesised (at most 8 runs per experiment, small
// paths only) and what synth writes (suite.yaml and the CSVs, with each run's start heading)
// must load back as a suite and compare. A world that synth accepts but whose suite does not
// load is a bug, reported as a crash.
#include <algorithm>
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/io/world.hpp"
#include "odomcov/io/suite_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "world.yaml");
  WorldFile world;
  try {
    world = load_world((dir / "world.yaml").string());
  } catch (const InputError&) {
    return 0;
  }
  for (WorldExperiment& ex : world.experiments) {
    if (sample_count(ex.path) > 20'000) return 0;
    ex.runs = std::min<std::int64_t>(ex.runs, 8);
  }
  const auto out = fuzz::scratch_dir("out");
  try {
    for (std::size_t i = 0; i < world.experiments.size(); ++i) {
      fuzz::write_text(out / (world.experiments[i].name + ".csv"),
                       measurements_csv(synthesize(world, i, 1), start_headings(world, i)));
    }
  } catch (const InputError&) {
    return 0;  // synth refuses the world (an expression not finite, runs beyond the limits)
  }
  fuzz::write_text(out / "suite.yaml", suite_yaml(world));
  try {
    const Suite suite = load_suite((out / "suite.yaml").string());
    // As the CLI: order 2 (the default) beyond its piece limit is refused, not computed.
    if (second_order_problem(suite, suite_model(suite).order).empty()) {
      fuzz::compare_both_ways(suite);
    }
  } catch (const InputError& e) {
    fuzz::invariant_failed(std::string("synth wrote a suite that does not load: ") + e.what());
  }
  return 0;
}
