// Fuzz target: a path config (SPEC "Path config"), then the first cheap stage of `theory` and
// `run`: the closed form, the sampling schedule, the engine with the model's effects and, on
// small paths, a 16-run validation (which exercises the simulator and the verdict).
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/measurement/validation.hpp"
#include "odomcov/io/config_io.hpp"

namespace {

/// Work above these sizes is skipped so that one input stays well under a second.
constexpr std::int64_t kMaxFuzzSamples = 20'000;
constexpr std::size_t kMaxFuzzPieces = 20'000;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "config.yaml");
  ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE({
    Config config = load_config((dir / "config.yaml").string());
    path_covariance(config.path, config.robot);
    noise_induced_mean(config.path, config.robot);
    sample_schedule(config.path);
    const auto pieces = model_pieces(config.path, config.robot.wheelbase_m);
    if (pieces.size() <= kMaxFuzzPieces) predict(pieces, config.robot, config.model_effects);
    if (sample_count(config.path) <= kMaxFuzzSamples) {
      config.simulation.runs = 16;
      validate(config, kDefaultAlpha, 1);
    }
  });
  return 0;
}
