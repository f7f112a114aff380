// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/engine/simulator.hpp".
#pragma once

#include "odomcov/engine/simulator.hpp"
