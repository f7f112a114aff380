// The rows of a wheel log (columns t, left, right, x, y, theta, docs/formats.md): what a
// suite's logs, `import csv` and `predict` read, checked in one place. Part of odomcov::io.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "io/csv.hpp"
#include "odomcov/closed_form/closed_form.hpp"

namespace odomcov::wheel_log {

/// One row: its time, the wheels' travel (times the scales) when the row gives it, the
/// reference pose when the row gives it (theta as written).
struct Row {
  int line = 0;
  double t = 0;
  bool wheels = false, reference = false;
  double left_m = 0, right_m = 0;
  Vector3 pose = Vector3::Zero();
};

/// A measured pose in `row` (x, y, theta from `first_column`) within the numeric domain
/// (limits.hpp): positions at most kMaxLength_m, the heading at most kMaxTurn_rad (it is wrapped,
/// but 1e5 rad is no angle anyone measured).
void check_pose(const std::string& file, const csv::Row& row, std::size_t first_column);

/// Where a log's lengths are measured from, for the numeric domain's check: from zero (a suite's
/// log, whose reference is in the run's start frame), or from the log's first wheel readings and
/// first reference pose (a raw recording: cumulative tick counters, a reference in a map or UTM
/// frame, which the importer re-expresses from the run's start).
enum class Origin { zero, first_row };

/// Every row of `table` (read from `file` with the columns t, left, right, then x, y, theta when
/// the log has a reference), checked: time strictly increasing, both wheels or neither, the
/// reference pose complete or absent, the wheels' travel (times the scales) and the pose within
/// the numeric domain (limits.hpp) from `origin`.
std::vector<Row> read(const std::string& file, const csv::Table& table, Origin origin, double left_scale = 1.0,
                      double right_scale = 1.0);

}  // namespace odomcov::wheel_log
