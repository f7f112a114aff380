// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/engine/second_order.hpp".
#pragma once

#include "odomcov/engine/second_order.hpp"
