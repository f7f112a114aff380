// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/measurement/suite.hpp" and "odomcov/io/suite_io.hpp".
#pragma once

#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_io.hpp"
