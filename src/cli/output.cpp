#include "output.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "odomcov/base/error.hpp"
#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/second_order.hpp"

namespace odomcov::cli {

json finite_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json to_json(const Vector3& v) { return json::array({v.x(), v.y(), v.z()}); }

json to_json(const Matrix3& m) {
  json rows = json::array();
  for (int i = 0; i < 3; ++i) rows.push_back(json::array({m(i, 0), m(i, 1), m(i, 2)}));
  return rows;
}

std::string sci(double value, int precision) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*e", precision, value);
  return buf;
}

std::string fixed(double value, int precision) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", precision, value);
  return buf;
}

std::string matrix_rows(const Matrix3& m, const std::string& indent, int precision) {
  std::ostringstream out;
  const int width = precision + 8;
  for (int i = 0; i < 3; ++i) {
    out << indent;
    for (int j = 0; j < 3; ++j) {
      const std::string cell = sci(m(i, j), precision);
      out << std::string(static_cast<std::size_t>(std::max(1, width - static_cast<int>(cell.size()))), ' ')
          << cell;
    }
    out << '\n';
  }
  return out.str();
}

json moments_json(const Vector3& mean, const Matrix3& cov) {
  const Matrix3 sc = std_corr_matrix(cov);
  Matrix3 corr = sc;
  corr.diagonal().setOnes();
  return {{"mean", to_json(mean)},
          {"cov", to_json(cov)},
          {"std", to_json(Vector3(sc.diagonal()))},
          {"corr", to_json(corr)}};
}

std::string moments_text(const Vector3& mean, const Matrix3& cov) {
  std::ostringstream out;
  out << "  mean is:\n";
  for (int i = 0; i < 3; ++i) out << "    " << sci(mean(i), 4) << "\n";
  out << "  covariance matrix is:\n" << matrix_rows(cov, "  ")
      << "  stand dev, correlation matrix is:\n" << matrix_rows(std_corr_matrix(cov), "  ");
  return out.str();
}

json test_json(const TestResult& t) {
  if (!t.valid) return {{"statistic", nullptr}, {"dof", t.dof}, {"p_value", nullptr}};
  return {{"statistic", t.statistic}, {"dof", t.dof}, {"p_value", t.p_value}};
}

std::string test_text(const TestResult& t) {
  if (!t.valid) return "not applicable (singular reference covariance or too few samples)";
  char buf[128];
  std::snprintf(buf, sizeof buf, "statistic %.4g, %d dof, p = %.4g", t.statistic, t.dof,
                t.p_value);
  return buf;
}

void check_output_path(const std::string& path) {
  namespace fs = std::filesystem;
  fs::path dir = fs::path(path).parent_path();
  if (dir.empty()) dir = ".";
  if (!fs::is_directory(dir)) throw UsageError(path + ": directory " + dir.string() + " does not exist");
  if (::access(dir.c_str(), W_OK) != 0) throw UsageError(path + ": directory is not writable");
  if (fs::is_directory(path)) throw UsageError(path + ": is a directory");
}

void check_output_dir(const std::string& out) {
  namespace fs = std::filesystem;
  std::string dir = out;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  const fs::path path(dir);
  const fs::path parent = path.has_parent_path() ? path.parent_path() : fs::path(".");
  if (!fs::is_directory(parent)) throw UsageError("--out: directory " + parent.string() + " does not exist");
  if (fs::exists(path) && !fs::is_directory(path)) throw UsageError("--out: " + dir + " is not a directory");
}

void check_alpha(double alpha) {
  if (!(alpha > 0.0 && alpha < 1.0)) throw UsageError("--alpha must be in (0, 1)");
}

void check_order(int order) {
  if (order != 1 && order != 2) throw UsageError("--order must be 1 or 2");
}

void check_second_order_size(const Suite& suite, int order) {
  if (const std::string e = second_order_problem(suite, order); !e.empty()) {
    throw InputError(suite.file, 0, "experiments", e);
  }
}

void check_finite_start(const Suite& suite, const SuiteModel& model, const std::string& what) {
  if (std::isfinite(log_likelihood(residuals(suite, model)))) return;
  throw InputError(suite.file, 0, "robot",
                   "the suite's model gives a log-likelihood of -inf (a singular predicted "
                   "covariance: k_left = k_right = 0 and no measurement_noise?); give it some "
                   "noise to start the " + what + " from");
}

void check_threads(int threads) {
  if (threads < 0 || threads > kMaxThreads) {
    throw UsageError("--threads must be in [0, " + std::to_string(kMaxThreads) + "] (0 = all cores)");
  }
}

std::string non_negative_integer(const std::string& text) {
  if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos) {
    return "expected a non-negative integer, got " + quote(text);
  }
  if (text.size() > 20 || (text.size() == 20 && text > "18446744073709551615")) {
    return "integer out of range (at most 2^64 - 1): " + quote(text);
  }
  return "";
}

void write_file_atomic(const std::string& path, const std::string& text) {
  namespace fs = std::filesystem;
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw std::runtime_error("cannot write " + path);
    }
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw std::runtime_error("cannot write " + path);
  }
}

void write_json_atomic(const std::string& path, const json& value) {
  write_file_atomic(path, value.dump(2) + "\n");
}

}  // namespace odomcov::cli

namespace odomcov::cli {

namespace {
std::string strip_trailing_slashes(std::string dir) {
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  return dir;
}
}  // namespace

StagedDir::StagedDir(const std::string& out) : out_(strip_trailing_slashes(out)) {
  namespace fs = std::filesystem;
  check_output_dir(out_);
  tmp_ = out_ + ".tmp." + std::to_string(::getpid());
  std::error_code ec;
  fs::remove_all(tmp_, ec);
  if (!fs::create_directory(tmp_, ec) || ec) {
    throw UsageError("--out: cannot create a directory next to " + one_line(out_, 200) + " (" +
                     ec.message() + ")");
  }
}

StagedDir::~StagedDir() {
  std::error_code ec;
  if (!tmp_.empty()) std::filesystem::remove_all(tmp_, ec);
}

void StagedDir::write(const std::string& relative, const std::string& text) {
  namespace fs = std::filesystem;
  const fs::path path = fs::path(tmp_) / relative;
  std::error_code ec;
  fs::create_directories(path.parent_path(), ec);
  errno = 0;
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  file << text;
  file.flush();
  if (ec || !file) {
    // Named by where it was going (the staging directory is removed), with the system's reason.
    const std::string why = ec ? ec.message() : errno != 0 ? std::strerror(errno) : "write failed";
    throw UsageError("--out: cannot write " + one_line((fs::path(out_) / relative).string(), 200) +
                     " (" + why + "); nothing was written");
  }
}

void StagedDir::commit() {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(out_)) {
    fs::rename(tmp_, out_, ec);
    if (ec) throw UsageError("--out: cannot create " + one_line(out_, 200) + " (" + ec.message() + ")");
  } else {
    // Into an existing directory: every destination is checked first, then each file is
    // renamed into place (renames within one file system do not fail part-way for space).
    std::vector<fs::path> files;
    for (const auto& entry : fs::recursive_directory_iterator(tmp_)) {
      if (!entry.is_regular_file()) continue;
      const fs::path target = fs::path(out_) / fs::relative(entry.path(), tmp_);
      if (fs::is_directory(target)) throw UsageError("--out: " + one_line(target.string(), 200) + " is a directory");
      files.push_back(entry.path());
    }
    for (const fs::path& f : files) {
      const fs::path target = fs::path(out_) / fs::relative(f, tmp_);
      fs::create_directories(target.parent_path(), ec);
      fs::rename(f, target, ec);
      if (ec) throw UsageError("--out: cannot write " + one_line(target.string(), 200) + " (" + ec.message() + ")");
    }
  }
  committed_ = true;
}

}  // namespace odomcov::cli
