#include "io/wheel_log.hpp"

#include <cmath>

#include "odomcov/closed_form/limits.hpp"

namespace odomcov::wheel_log {
namespace {

/// Cell `c` of `row` times `scale`, within the numeric domain (`check`: a length [m] or an angle
/// [rad], limits.hpp) measured from `*from`; with `from` null, from the value itself (a raw log's
/// first value: finite is all it needs to be).
double value_of(const std::string& file, const csv::Row& row, std::size_t c, double scale, const double* from,
                std::string (*check)(double) = limits::check_length) {
  const double v = scale * row.number(c);
  if (const std::string e = std::isfinite(v) ? check(v - (from ? *from : v)) : check(v); !e.empty()) {
    csv::fail(file, row.line, row.meta->columns[c], e);
  }
  return v;
}

/// Pose column k (x, y, theta) of a row starting at `first_column`, measured from `from`.
double pose_value(const std::string& file, const csv::Row& row, std::size_t first_column, int k, const double* from) {
  return value_of(file, row, first_column + static_cast<std::size_t>(k), 1.0, from,
                  k == 2 ? limits::check_angle : limits::check_length);
}

/// Where the lengths of a log are measured from: zero, or (Origin::first_row) its first wheel
/// readings and first reference pose once read.
struct Origins {
  bool wheels_seen, pose_seen;
  double left0 = 0.0, right0 = 0.0;
  Vector3 pose0 = Vector3::Zero();
};

/// One row, checked (see read), after `previous` (null for the first).
Row read_row(const std::string& file, const csv::Row& row, const Row* previous, double left_scale,
             double right_scale, Origins& o) {
  Row r;
  r.line = row.line;
  r.t = row.number(0);
  if (previous && !(r.t > previous->t)) csv::fail(file, row.line, "t", "time must increase strictly");
  r.wheels = !row.empty(1);
  if (r.wheels != !row.empty(2)) csv::fail(file, row.line, "left,right", "give both wheels or neither");
  const bool has_pose = row.cells.size() >= 6;  // else a log of t, left, right
  r.reference = has_pose && !row.empty(3);
  if (has_pose && (r.reference != !row.empty(4) || r.reference != !row.empty(5))) {
    csv::fail(file, row.line, "x,y,theta", "a reference pose needs all of x, y and theta");
  }
  if (r.wheels) {
    r.left_m = value_of(file, row, 1, left_scale, o.wheels_seen ? &o.left0 : nullptr);
    r.right_m = value_of(file, row, 2, right_scale, o.wheels_seen ? &o.right0 : nullptr);
    if (!o.wheels_seen) o.left0 = r.left_m, o.right0 = r.right_m, o.wheels_seen = true;
  }
  if (r.reference) {
    for (int k = 0; k < 3; ++k) r.pose[k] = pose_value(file, row, 3, k, o.pose_seen ? &o.pose0[k] : nullptr);
    if (!o.pose_seen) o.pose0 = r.pose, o.pose_seen = true;
  }
  return r;
}

}  // namespace

void check_pose(const std::string& file, const csv::Row& row, std::size_t first_column) {
  static constexpr double kZero = 0.0;
  for (int k = 0; k < 3; ++k) pose_value(file, row, first_column, k, &kZero);
}

std::vector<Row> read(const std::string& file, const csv::Table& table, Origin origin, double left_scale,
                      double right_scale) {
  std::vector<Row> rows;
  rows.reserve(table.rows.size());
  const bool from_zero = origin == Origin::zero;
  Origins o{from_zero, from_zero};
  for (const csv::Row& row : table.rows) {
    rows.push_back(read_row(file, row, rows.empty() ? nullptr : &rows.back(), left_scale, right_scale, o));
  }
  return rows;
}

}  // namespace odomcov::wheel_log
