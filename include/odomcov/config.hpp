// Deprecated include path, kept for one release (docs/library.md, "Include paths"): the
// header now lives in its layer folder. Include "odomcov/measurement/config.hpp" and "odomcov/io/config_io.hpp".
#pragma once

#include "odomcov/measurement/config.hpp"
#include "odomcov/io/config_io.hpp"
