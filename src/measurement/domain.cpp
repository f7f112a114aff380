#include "odomcov/measurement/domain.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "odomcov/base/format.hpp"
#include "odomcov/measurement/residual_features.hpp"

namespace odomcov {
namespace {

/// One feature of the domain: its name, unit, where it lives in a Domain and in PathFeatures.
struct Feature {
  const char* name;
  const char* unit;
  Domain::Range Domain::*range;
  double PathFeatures::*value;
};
constexpr Feature kFeatures[] = {
    {"speed", " m/s", &Domain::speed_mps, &PathFeatures::speed_mps},
    {"spin fraction", "", &Domain::spin_fraction, &PathFeatures::spin_fraction},
    {"length", " m", &Domain::length_m, &PathFeatures::distance_m},
    {"duration", " s", &Domain::duration_s, &PathFeatures::duration_s},
};

/// A range that holds nothing yet: the first value sets both ends.
Domain::Range empty_range() {
  return {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
}

void extend(Domain::Range& r, double v) {
  r.lo = std::min(r.lo, v);
  r.hi = std::max(r.hi, v);
}

/// The features of each run of an experiment, extended into `d`.
void extend(Domain& d, const SuiteExperiment& ex, double wheelbase_m) {
  for (const SuiteRun& run : ex.runs) {
    const PathFeatures f = path_features(ex, run, wheelbase_m);
    for (const Feature& feature : kFeatures) extend(d.*feature.range, f.*feature.value);
  }
}

std::string number(double v) { return format_number(v, "%.3g"); }

}  // namespace

Domain training_domain(const Suite& suite, double wheelbase_m) {
  Domain d;
  for (const Feature& feature : kFeatures) d.*feature.range = empty_range();
  for (const SuiteExperiment& ex : suite.experiments) extend(d, ex, wheelbase_m);
  return d;
}

std::vector<std::string> extrapolation(const Domain& domain, const SuiteExperiment& ex, double wheelbase_m) {
  Domain seen;
  for (const Feature& feature : kFeatures) seen.*feature.range = empty_range();
  extend(seen, ex, wheelbase_m);
  std::vector<std::string> out;
  for (const Feature& feature : kFeatures) {
    const Domain::Range& train = domain.*feature.range;
    const Domain::Range& here = seen.*feature.range;
    const std::string range = " the training range " + number(train.lo) + "-" + number(train.hi) + feature.unit;
    // The domain is written with 9 digits: a run on its edge reads back inside.
    const double slack = 1e-8 * std::max(std::abs(train.lo), std::abs(train.hi));
    if (here.hi > train.hi + slack) {
      out.push_back(std::string(feature.name) + " " + number(here.hi) + feature.unit + " is above" + range);
    }
    if (here.lo < train.lo - slack) {
      out.push_back(std::string(feature.name) + " " + number(here.lo) + feature.unit + " is below" + range);
    }
  }
  return out;
}

}  // namespace odomcov
