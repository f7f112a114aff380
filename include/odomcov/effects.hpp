// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/effects/effects.hpp".
#pragma once

#include "odomcov/effects/effects.hpp"
