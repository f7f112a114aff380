// Reading measurement suites (docs/formats.md, "Measurement suite") and the files they name.
#pragma once

#include <string>

#include "odomcov/measurement/suite.hpp"

namespace odomcov {

/// Reads and validates a suite and every file it names. Throws InputError (file:line: key) for
/// a missing file, an empty CSV, wrong columns, a value that is not a finite number, duplicate
/// run ids, a log without a final reference pose, time that does not increase, ...
Suite load_suite(const std::string& file);

}  // namespace odomcov
