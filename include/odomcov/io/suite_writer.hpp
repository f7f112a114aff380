// Writing a measurement suite (docs/formats.md, "Measurement suite"). One writer serves every
// producer of suites: `synth` (path experiments with measurement CSVs), `import optiodom` and
// `import csv` (experiments of logged runs). Names and file names are quoted as YAML needs, so
// any experiment name reads back unchanged.
#pragma once

#include <string>
#include <vector>

#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/path.hpp"
#include "odomcov/measurement/suite.hpp"

namespace odomcov {

/// Everything a suite file holds, as plain data.
struct SuiteDocument {
  std::vector<std::string> comments;  // header comment lines (without the leading '#')
  std::string name;
  Robot robot;                        // the nominal robot: wheelbase [m], k_left, k_right [m^(1/2)]
  MeasurementNoise measurement_noise;  // written as {xy [m], theta_deg [deg]}
  EffectList model_effects;           // written as model.effects when not empty

  struct Experiment {
    std::string name;
    /// Path experiments: the `path` block as YAML text (any style; written back in its own
    /// style) and the measurement CSV, relative to the suite file.
    std::string path_yaml;
    std::string measurements;
    /// Logged experiments: one encoder log per run, relative to the suite file.
    std::vector<std::string> logs;
    /// The experiment's group (written as `group:` when not empty): runs of one group share
    /// group_variation's draw (a session, a day).
    std::string group;
    /// The experiment's kind (written as `kind:` when not empty; the loader's default is the
    /// name up to its first '-').
    std::string kind;
  };
  std::vector<Experiment> experiments;
};

/// One file of an imported suite: its path relative to the output directory and its text.
/// Importers return every file before the caller writes any, so bad input writes nothing.
struct ImportedFile {
  std::string path;
  std::string text;
};

/// One experiment of an import, for the importer's report.
struct ImportSummary {
  std::string experiment;
  std::size_t runs = 0;
  double mean_travel_m = 0.0;            // encoder travel per run [m] (each importer says how)
  double mean_turn_rad = 0.0;            // encoder: signed heading change
  double mean_reference_travel_m = -1.0;  // the reference's own travel; < 0 when not measured
};

/// The suite.yaml text of a document. Throws std::invalid_argument when an experiment has
/// neither (path_yaml and measurements) nor logs, or an unknown model effect.
std::string suite_yaml(const SuiteDocument& suite);

}  // namespace odomcov
