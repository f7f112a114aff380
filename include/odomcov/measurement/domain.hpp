// The domain of validity of a calibrated model: the range of motion its training runs covered
// (speed, spin fraction, length and duration per run), and which experiments lie outside it. A
// model predicts inside its training domain; outside, it extrapolates, and compare and
// calibrate --holdout say where.
#pragma once

#include <string>
#include <vector>

#include "odomcov/measurement/suite.hpp"

namespace odomcov {

/// The training domain of a suite: over its runs, the lowest and highest of each run's mean
/// speed, spin fraction, length (mean wheel travel) and duration (path_features, at the
/// wheelbase given).
Domain training_domain(const Suite& suite, double wheelbase_m);

/// Where an experiment lies outside a domain, in words, one entry per feature and side, e.g.
/// "speed 0.104 m/s is above the training range 0.0312-0.0498 m/s": the experiment's highest
/// run value above the range, its lowest below it. Empty when every run lies inside.
std::vector<std::string> extrapolation(const Domain& domain, const SuiteExperiment& ex, double wheelbase_m);

}  // namespace odomcov
