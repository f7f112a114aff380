// Fuzz target: a sweep file and its base config (section "#@ base.yaml"); load_sweep validates
// every grid point. On a small first point, one 16-run validation and its CSV metrics.
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/io/sweep.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "sweep.yaml");
  ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE({
    const SweepPlan plan = load_sweep((dir / "sweep.yaml").string());
    Config config = plan.point_config(0);
    if (sample_count(config.path) <= 20'000) {
      config.simulation.runs = 16;
      sweep_metrics(validate(config, kDefaultAlpha, 1));
    }
  });
  return 0;
}
