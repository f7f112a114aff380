// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/closed_form/path.hpp".
#pragma once

#include "odomcov/closed_form/path.hpp"
