// Parameter sweeps (docs/formats.md, "Sweep file"): a base path config and a grid of values
// for any of its numeric keys, plus the convenience axes noise_scale and path_scale.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "odomcov/measurement/config.hpp"
#include "odomcov/measurement/validation.hpp"

namespace odomcov {

/// The parsed base config (opaque: its type is private to the library).
struct SweepBase;

struct SweepAxis {
  std::string name;  // dotted config key, "noise_scale" or "path_scale"
  std::vector<double> values;
  int line = 0;  // of the axis in the sweep file
};

class SweepPlan {
 public:
  std::string file;       // the sweep file
  std::string base_file;  // resolved relative to the sweep file
  std::int64_t runs = 0;  // 0: keep each point's simulation.runs
  std::uint64_t seed = 1;
  std::vector<SweepAxis> axes;  // in the order written; the first varies slowest

  std::size_t point_count() const;
  /// The axis values of point i (row-major over the axes in order).
  std::vector<double> point_values(std::size_t i) const;
  /// Seed of point i: SplitMix64 of (seed, i), so a point's result does not depend on which
  /// other points are run (sharding).
  std::uint64_t point_seed(std::size_t i) const;
  /// The validated config of point i. Throws InputError naming the sweep file and axis.
  Config point_config(std::size_t i) const;

  std::shared_ptr<const SweepBase> base;  // the parsed base config

 private:
  Config point_config_unguarded(std::size_t i) const;
};

/// Reads and validates a sweep file, and every grid point's config, before any work starts.
SweepPlan load_sweep(const std::string& file);

/// Scales a path geometrically: each interval's centre travel d becomes s d with its heading
/// change kept (lines and arc radii scale by s, turns on the spot do not), and its duration
/// changes so that the faster wheel keeps its speed.
Path scale_path(const Path& path, double scale);

/// The metrics of one sweep row (docs/formats.md, "Sweep file": the CSV columns).
struct SweepMetrics {
  Vector3 std_rel_err = Vector3::Zero();  // simulated std / theory std - 1
  double max_corr_diff = 0.0;             // max |corr_sim - corr_theory| off the diagonal
  Vector3 bias_se = Vector3::Zero();      // (sim mean - theory mean) / (sim std / sqrt(n))
  double p_mean = 1.0;
  double p_cov = 1.0;
  double nees_mean = 0.0;
  Verdict verdict;
};
SweepMetrics sweep_metrics(const Validation& v);

/// The CSV column names after the axis names.
const std::vector<std::string>& sweep_metric_columns();

}  // namespace odomcov
