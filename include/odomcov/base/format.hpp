// Number formatting shared by the library's reports and the YAML it writes.
#pragma once

#include <cstdio>
#include <string>

namespace odomcov {

/// A printf-formatted number. The default, "%.10g", keeps ten significant digits: enough for a
/// fitted parameter pasted back into YAML, short enough to read.
inline std::string format_number(double v, const char* format = "%.10g") {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

}  // namespace odomcov
