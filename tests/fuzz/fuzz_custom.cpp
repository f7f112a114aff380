// Fuzz target: a list of effects, custom ones with their expressions (diagnose --candidates'
// input), then the first cheap stage: the model side on a short timed path that has lines,
// spins, arcs and a reversal (every per-sample variable takes several values, the start heading
// is 0.7 rad), at order 1 and 2, eight simulated runs of its world side, and the writer's round
// trip: what effect_yaml writes must load back and write the same. A
// list that loads but whose effects throw anything but InputError, or do not round-trip, is a
// bug, reported as a crash.
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/second_order.hpp"
#include "odomcov/engine/simulator.hpp"
#include "odomcov/io/config_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "effects.yaml");
  EffectList effects;
  try {
    effects = load_effects((dir / "effects.yaml").string());
  } catch (const InputError&) {
    return 0;
  }
  std::string text;
  for (const EffectSpec& e : effects) text += effect_yaml(e) + "\n";
  const auto out = fuzz::scratch_dir("out");
  fuzz::write_text(out / "effects.yaml", text);
  try {
    // The writer keeps ten significant digits (readable snippets), so the round trip is checked
    // as a fixed point: what was written loads back, and writing that again gives the same text.
    std::string again;
    for (const EffectSpec& e : load_effects((out / "effects.yaml").string())) again += effect_yaml(e) + "\n";
    if (again != text) fuzz::invariant_failed("effect_yaml does not round-trip:\n" + text + "---\n" + again);
  } catch (const InputError& e) {
    fuzz::invariant_failed(std::string("effect_yaml wrote a list that does not load: ") + e.what());
  }
  const Robot robot{0.4, {1e-3, 1e-3}};
  const std::vector<ArcSegment> pieces{{0.2, 0.2}, {0.2, 0.2}, {-0.1, 0.1}, {0.15, 0.25}, {-0.2, -0.2}, {0.0, 0.1}};
  const std::vector<double> durations{0.5, 1.0, 0.5, 0.4, 1.0, 0.3};
  ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE({
    predict(pieces, durations, robot, effects, 0.7);  // a start heading for `heading`
    predict_second_order(pieces, durations, robot, effects, 0.7);
    // The world side on the same pieces: per-run draws, lateral slips, noise factors.
    Simulator(robot, pieces, durations, effects, 0.7).errors(1, 0, 8, 1);
  });
  return 0;
}
