// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/measurement/calibration.hpp".
#pragma once

#include "odomcov/measurement/calibration.hpp"
