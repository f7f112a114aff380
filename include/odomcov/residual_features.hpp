// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/measurement/residual_features.hpp".
#pragma once

#include "odomcov/measurement/residual_features.hpp"
