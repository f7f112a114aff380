// Reading path configs and effect lists from YAML (docs/formats.md, "Path config").
#pragma once

#include <cstdint>
#include <string>

#include "odomcov/effects/effects.hpp"
#include "odomcov/measurement/config.hpp"

namespace odomcov {

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
