// Fuzz target: a world file (`synth`'s input), then the closed form of each experiment's path.
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/io/world.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "world.yaml");
  ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE({
    const WorldFile world = load_world((dir / "world.yaml").string());
    for (const WorldExperiment& ex : world.experiments) {
      path_covariance(ex.path, world.robot);
      sample_schedule(ex.path);
    }
  });
  return 0;
}
