// Import of the OptiOdom recordings [Sousa22] (data/optiodom, MIT licence) as a
// measurement suite with per-run encoder logs.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_writer.hpp"

namespace odomcov {

/// What an experiment's `group:` is: its session (the session directory's name, as the
/// recordings write it: one group per session) or the recording day the session belongs to.
enum class OptiOdomGroup { session, day };

struct OptiOdomOptions {
  std::vector<std::string> sessions;  // session directories, e.g. .../diff/square/230620202042
  std::optional<double> wheelbase_m;  // nominal robot; default: the sessions' metadata Li
  std::optional<std::pair<double, double>> diameters_m;  // (left, right); default: metadata Di
  double k = 1e-3;  // nominal wheel noise for the suite's robot (to be fitted)
  MeasurementNoise measurement_noise{0.001, 0.1 * kDegToRad};  // OptiTrack, conservative
  std::string name = "optiodom";
  OptiOdomGroup group = OptiOdomGroup::session;
};

/// Reads every session (metadata and run files, validated) and returns the suite's files:
/// suite.yaml and one log per run (t, cumulative left and right metres, and the OptiTrack end
/// pose in the last row). Encoder ticks become metres as pi D / (ngear encRes): the data show
/// no quadrature factor (README). Runs are grouped into experiments by path type (the session's
/// parent folder), session and, for the calibration paths, turning direction (cw, ccw or
/// straight from the sign of the encoders' total heading change). Each experiment's `group` is
/// its session, the session directory's name (OptiOdomGroup::session), or the recording day
/// (OptiOdomGroup::day): the evening its session directory (named DDMMYYYYhhmm, the start time)
/// belongs to, as YYYY-MM-DD, a start before 06:00 counting to the evening before.
std::vector<ImportedFile> import_optiodom(const OptiOdomOptions& options,
                                          std::vector<ImportSummary>* summary = nullptr);

}  // namespace odomcov
