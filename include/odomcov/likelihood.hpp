// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/measurement/likelihood.hpp".
#pragma once

#include "odomcov/measurement/likelihood.hpp"
