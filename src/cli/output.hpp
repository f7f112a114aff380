// Output helpers shared by the subcommands: number and matrix formatting, JSON blocks, and
// writing files atomically (a file is either complete or not there).
#pragma once

#include <nlohmann/json.hpp>

#include <string>

#include "odomcov/closed_form/closed_form.hpp"
#include "odomcov/engine/statistics.hpp"
#include "odomcov/measurement/suite.hpp"

namespace odomcov::cli {

using nlohmann::json;

json to_json(const Vector3& v);
json to_json(const Matrix3& m);

/// "%.4e"-style scientific, or fixed with `precision` decimals.
std::string sci(double value, int precision = 4);
std::string fixed(double value, int precision);

/// Rows of a 3x3 matrix, each prefixed with `indent`, columns right-aligned.
std::string matrix_rows(const Matrix3& m, const std::string& indent, int precision = 4);


/// The {mean, cov, std, corr} block (docs/json.md, "run").
json moments_json(const Vector3& mean, const Matrix3& cov);

/// [Kleeman95] §7 layout: "mean is:", "covariance matrix is:", "stand dev, correlation matrix
/// is:", each as indented rows.
std::string moments_text(const Vector3& mean, const Matrix3& cov);

/// A finite number as JSON; null otherwise (no standard error, not cross-validated).
json finite_or_null(double v);

/// {statistic, dof, p_value}; statistic and p_value are null when the test is not applicable.
json test_json(const TestResult& t);
std::string test_text(const TestResult& t);

/// Fails with a usage error (exit 2) unless the output's directory exists and is writable;
/// called before any work starts.
void check_output_path(const std::string& path);

/// The same for an output directory (`--out DIR` of synth and import): its parent must exist,
/// and it must be a directory if it exists.
void check_output_dir(const std::string& dir);

/// Usage checks shared by the subcommands: --alpha in (0, 1), --threads in [0, kMaxThreads]
/// (TBB caps its workers at the machine's cores anyway; more is a typo, not a request).
inline constexpr int kMaxThreads = 1024;
void check_alpha(double alpha);
/// --order must be 1 (first order) or 2 (the order-2 model).
void check_order(int order);
void check_threads(int threads);

/// fit and diagnose: a suite whose model gives a log-likelihood that is not finite (no wheel
/// noise and no measurement noise: a singular predicted covariance) gives the optimiser nothing
/// to climb. Refused with an InputError naming the suite's robot line (exit 2), never a fit that
/// prints -inf or "inf" improvements.
/// compare, fit and diagnose with --order 2: every experiment's order-2 prediction must stay
/// within kMaxSecondOrderPieces (limits.hpp; its cost is quadratic), else an InputError naming
/// the experiment (exit 2) before any work.
void check_second_order_size(const Suite& suite, int order);

void check_finite_start(const Suite& suite, const SuiteModel& model, const std::string& what);

/// CLI11 check for unsigned options (seeds): digits only, so "-1" is refused instead of
/// wrapping to 2^64 - 1, and the value must fit 64 bits.
std::string non_negative_integer(const std::string& text);

/// Writes `text` to `path` via a temporary file and rename.
void write_file_atomic(const std::string& path, const std::string& text);
void write_json_atomic(const std::string& path, const json& value);

/// An output directory written all or nothing (synth, import): files go into a temporary
/// sibling directory, created at once (so an unwritable destination fails before any work), and
/// commit() moves them into place; without commit() nothing is left behind. A trailing '/' is
/// allowed and the directory need not exist (its parent must).
class StagedDir {
 public:
  explicit StagedDir(const std::string& out);
  ~StagedDir();
  StagedDir(const StagedDir&) = delete;
  StagedDir& operator=(const StagedDir&) = delete;
  /// Writes `relative` (may contain sub-directories) into the staging directory.
  void write(const std::string& relative, const std::string& text);
  void commit();
  const std::string& final_dir() const { return out_; }

 private:
  std::string out_, tmp_;
  bool committed_ = false;
};

/// A usage error: reported as one line, exit code 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace odomcov::cli
