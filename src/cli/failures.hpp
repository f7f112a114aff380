// The plain words of compare's failures ("where it fails"): the library reports them as data
// (odomcov::Failure), the command line and the Python module word them here.
#pragma once

#include <string>
#include <vector>

#include "odomcov/measurement/comparison.hpp"

namespace odomcov::cli {

/// One failure in words, e.g. "spin-cw-720: theta mean 0.1255 rad, 156.2 standard errors from
/// the predicted 0".
std::string failure_text(const Comparison& c, const Failure& f);

/// Every failure of the comparison, worst first (docs/json.md, "compare": failures).
std::vector<std::string> failure_texts(const Comparison& c);

/// Why a comparison of the suite has no kurtosis test (Comparison::kurtosis not valid), in words.
std::string no_kurtosis_reason(const Suite& suite);

}  // namespace odomcov::cli
