#include "odomcov/suite.hpp"

#include <tbb/parallel_for.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>

#include "csv.hpp"
#include "odomcov/config.hpp"
#include "odomcov/propagation.hpp"
#include "yaml_util.hpp"

namespace odomcov {
namespace {

using yaml::Where;

constexpr double kDegToRad = M_PI / 180.0;

std::vector<SuiteRun> load_measurements(const std::string& csv_file, const Vector3& odometry) {
  const csv::Table table = csv::read(csv_file, {"run", "x", "y", "theta"});
  std::vector<SuiteRun> runs;
  std::set<std::string> ids;
  for (const csv::Row& row : table.rows) {
    SuiteRun run;
    run.id = row.text(0);
    if (run.id.empty()) csv::fail(csv_file, row.line, "run", "empty run id");
    if (!ids.insert(run.id).second) {
      csv::fail(csv_file, row.line, "run", "duplicate run id '" + run.id + "'");
    }
    run.measured = {row.number(1), row.number(2), row.number(3)};
    run.odometry = odometry;
    run.source = csv_file + ":" + std::to_string(row.line);
    runs.push_back(std::move(run));
  }
  return runs;
}

SuiteRun load_log(const std::string& log_file, double wheelbase_m) {
  const csv::Table table = csv::read(log_file, {"t", "left", "right", "x", "y", "theta"});
  SuiteRun run;
  run.id = std::filesystem::path(log_file).stem().string();
  run.source = log_file;
  Vector3 odometry = Vector3::Zero();
  double t = 0, left = 0, right = 0;
  int reference_line = 0;
  std::size_t reference_pieces = 0;
  for (std::size_t i = 0; i < table.rows.size(); ++i) {
    const csv::Row& row = table.rows[i];
    const double ti = row.number(0), li = row.number(1), ri = row.number(2);
    if (i > 0) {
      if (!(ti > t)) csv::fail(log_file, row.line, "t", "time must increase strictly");
      run.pieces.push_back({li - left, ri - right});
      odometry = drive(odometry, run.pieces.back(), wheelbase_m);
    }
    t = ti, left = li, right = ri;
    const bool has_x = !row.empty(3), has_y = !row.empty(4), has_theta = !row.empty(5);
    if (has_x || has_y || has_theta) {
      if (!(has_x && has_y && has_theta)) {
        csv::fail(log_file, row.line, "x,y,theta", "a reference pose needs all of x, y and theta");
      }
      run.measured = {row.number(3), row.number(4), row.number(5)};
      run.odometry = odometry;
      reference_line = row.line;
      reference_pieces = run.pieces.size();
    }
  }
  if (reference_line == 0) {
    csv::fail(log_file, table.rows.back().line, "x,y,theta", "the log has no reference pose");
  }
  run.pieces.resize(reference_pieces);  // the model covers the path up to the last reference
  run.source = log_file + ":" + std::to_string(reference_line);
  return run;
}

}  // namespace

Matrix3 MeasurementNoise::covariance() const {
  return Vector3(xy_m * xy_m, xy_m * xy_m, theta_rad * theta_rad).asDiagonal();
}

Vector3 SuiteRun::error() const {
  return {measured.x() - odometry.x(), measured.y() - odometry.y(),
          wrap_angle(measured.z() - odometry.z())};
}

Vector3 sampled_end_pose(const Path& path, double wheelbase_m) {
  Vector3 pose = Vector3::Zero();
  for (const SampleRun& run : sample_schedule(path)) {
    const double n = static_cast<double>(run.count);
    // `count` samples of one increment lie on one arc: drive it in one step.
    pose = drive(pose, {n * run.increment.left_m, n * run.increment.right_m}, wheelbase_m);
  }
  return pose;
}

std::vector<ArcSegment> run_pieces(const SuiteExperiment& experiment, const SuiteRun& run,
                                   double wheelbase_m) {
  return experiment.logged ? run.pieces : model_pieces(experiment.path, wheelbase_m);
}

Suite load_suite(const std::string& file) {
  const YAML::Node root = yaml::load_file(file);
  const Where where{file, ""};
  yaml::require_map(where, root,
                    {"name", "robot", "measurement_noise", "model", "experiments"});
  Suite suite;
  suite.file = file;
  suite.name = root["name"] ? yaml::to_string(where.child("name"), root["name"])
                            : std::filesystem::path(file).stem().string();
  suite.robot = parse_robot(yaml::require(where, root, "robot"), file, "robot");
  if (const YAML::Node noise = root["measurement_noise"]) {
    const Where nw = where.child("measurement_noise");
    yaml::require_map(nw, noise, {"xy", "theta_deg"});
    suite.measurement_noise.xy_m = yaml::optional_number(nw, noise, "xy").value_or(0.0);
    suite.measurement_noise.theta_rad =
        yaml::optional_number(nw, noise, "theta_deg").value_or(0.0) * kDegToRad;
    if (suite.measurement_noise.xy_m < 0) yaml::fail(nw.child("xy"), noise["xy"], "must be >= 0");
    if (suite.measurement_noise.theta_rad < 0) {
      yaml::fail(nw.child("theta_deg"), noise["theta_deg"], "must be >= 0");
    }
  }
  if (const YAML::Node model = root["model"]) {
    yaml::require_map(where.child("model"), model, {"effects"});
    if (model["effects"]) suite.model_effects = parse_effects(model["effects"], file, "model.effects");
  }
  const Where ew = where.child("experiments");
  const YAML::Node list = yaml::require(where, root, "experiments");
  yaml::require_sequence(ew, list);
  if (list.size() == 0) yaml::fail(ew, list, "need at least one experiment");
  const std::filesystem::path dir = std::filesystem::path(file).parent_path();
  std::set<std::string> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const Where xw = ew.index(i);
    const YAML::Node node = list[i];
    yaml::require_map(xw, node, {"name", "path", "measurements", "logs"});
    SuiteExperiment ex;
    ex.name = yaml::to_string(xw.child("name"), yaml::require(xw, node, "name"));
    if (!names.insert(ex.name).second) yaml::fail(xw.child("name"), node["name"], "duplicate experiment name");
    const bool has_measurements = node["measurements"].IsDefined();
    const bool has_logs = node["logs"].IsDefined();
    if (has_measurements == has_logs) {
      yaml::fail(xw, node, "give either 'path' with 'measurements', or 'logs'");
    }
    if (has_measurements) {
      ex.path = parse_path(yaml::require(xw, node, "path"), file, xw.child("path").key,
                           suite.robot.wheelbase_m);
      const std::string csv_file =
          (dir / yaml::to_string(xw.child("measurements"), node["measurements"])).string();
      ex.runs = load_measurements(csv_file, sampled_end_pose(ex.path, suite.robot.wheelbase_m));
    } else {
      if (node["path"]) yaml::fail(xw.child("path"), node["path"], "logged runs carry their own path");
      ex.logged = true;
      const Where lw = xw.child("logs");
      yaml::require_sequence(lw, node["logs"]);
      if (node["logs"].size() == 0) yaml::fail(lw, node["logs"], "need at least one log");
      std::set<std::string> ids;
      for (std::size_t j = 0; j < node["logs"].size(); ++j) {
        const std::string log = (dir / yaml::to_string(lw.index(j), node["logs"][j])).string();
        SuiteRun run = load_log(log, suite.robot.wheelbase_m);
        if (!ids.insert(run.id).second) yaml::fail(lw.index(j), node["logs"][j], "duplicate log");
        ex.runs.push_back(std::move(run));
      }
    }
    suite.experiments.push_back(std::move(ex));
  }
  return suite;
}

}  // namespace odomcov

namespace odomcov {
namespace {

constexpr int kDim = 3;
/// The LRT's Bartlett-corrected chi^2 is accurate from about ten runs; below, the NEES test.
constexpr std::int64_t kMinRunsForLrt = 10;
/// chi^2_3 95% point (Abramowitz & Stegun 26.8): the NEES bound of "outside_95".
constexpr double kChi2_3_95 = 7.814727903251178;

const char* const kComponent[kDim] = {"x", "y", "theta"};
const char* const kUnit[kDim] = {"m", "m", "rad"};

std::string num(double v, const char* format = "%.4g") {
  char buf[40];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

double student_t_two_sided(double t, double dof) {
  if (!(dof > 0) || !std::isfinite(t)) return std::isfinite(t) ? 1.0 : 0.0;
  return 2.0 * boost::math::cdf(boost::math::complement(boost::math::students_t(dof), std::abs(t)));
}

double chi2_two_sided(double x, double dof) {
  const boost::math::chi_squared d(dof);
  const double lower = boost::math::cdf(d, std::max(x, 0.0));
  return std::min(1.0, 2.0 * std::min(lower, 1.0 - lower));
}

/// Model error of a path experiment's runs at the model's wheelbase.
Vector3 error_against(const Vector3& measured, const Vector3& odometry) {
  return {measured.x() - odometry.x(), measured.y() - odometry.y(),
          wrap_angle(measured.z() - odometry.z())};
}

ExperimentComparison compare_experiment(const SuiteExperiment& ex,
                                        const std::vector<RunResidual>& res, double alpha_test,
                                        std::vector<Vector3>& whitened) {
  ExperimentComparison c;
  c.name = ex.name;
  c.n = static_cast<std::int64_t>(res.size());
  const double n = static_cast<double>(c.n);
  std::vector<Vector3> errors, raw;
  whitened.clear();
  Matrix3 mean_cov = Matrix3::Zero();
  MomentAccumulator predicted_means;
  for (const RunResidual& r : res) {
    errors.push_back(r.error);
    raw.push_back(r.error - r.mean);
    const Eigen::LLT<Matrix3> llt(r.cov);
    const Vector3 z = llt.matrixL().solve(r.error - r.mean);
    whitened.push_back(z);
    const double nees = z.squaredNorm();
    c.nees_mean += nees / n;
    c.outside_95 += (nees > kChi2_3_95 ? 1.0 : 0.0) / n;
    c.log_likelihood += gaussian_log_density(r.error, r.mean, r.cov);
    mean_cov += r.cov / n;
    predicted_means.add(r.mean);
  }
  c.measured = moments(errors);
  c.predicted_mean = predicted_means.mean();
  c.predicted_cov = mean_cov + predicted_means.scatter() / n;

  const SampleMoments z = moments(whitened);
  c.mean_test = c.n > kDim ? hotelling_test(z, Vector3::Zero())
                           : mean_test_known_covariance(z, Vector3::Zero(), Matrix3::Identity());
  if (c.n >= kMinRunsForLrt) {
    c.cov_test = covariance_test(z, Matrix3::Identity());
    c.cov_method = "lrt";
  } else {
    c.cov_test.statistic = c.nees_mean * n;
    c.cov_test.dof = kDim * static_cast<int>(c.n);
    c.cov_test.p_value = chi2_two_sided(c.cov_test.statistic, c.cov_test.dof);
    c.cov_method = "nees";
  }
  const SampleMoments r = moments(raw);
  for (int k = 0; k < kDim; ++k) {
    // Like the joint test: the sample's own standard error (Student t) when the experiment is
    // large enough for Hotelling, else the predicted one (normal).
    const double sd = std::sqrt(std::max(r.cov(k, k), 0.0));
    if (c.n > kDim && sd > 0) {
      c.mean_t(k) = r.mean(k) / (sd / std::sqrt(n));
      c.mean_p(k) = student_t_two_sided(c.mean_t(k), n - 1);
    } else {
      c.mean_t(k) = r.mean(k) / std::sqrt(mean_cov(k, k) / n);
      c.mean_p(k) = 2.0 * boost::math::cdf(boost::math::complement(boost::math::normal(),
                                                                   std::abs(c.mean_t(k))));
    }
    if (c.n > 1 && mean_cov(k, k) > 0) {
      c.variance_ratio(k) = r.cov(k, k) / mean_cov(k, k);
      c.variance_p(k) = chi2_two_sided((n - 1) * c.variance_ratio(k), n - 1);
    }
  }
  const bool reject = (c.mean_test.valid && c.mean_test.p_value < alpha_test) ||
                      (c.cov_test.valid && c.cov_test.p_value < alpha_test);
  c.verdict = reject ? "inconsistent" : "consistent";
  return c;
}

std::vector<std::string> failure_words(const ExperimentComparison& c, double alpha_test) {
  std::vector<std::string> words;
  if (c.mean_test.valid && c.mean_test.p_value < alpha_test) {
    int worst = 0;
    for (int k = 1; k < kDim; ++k) worst = c.mean_p(k) < c.mean_p(worst) ? k : worst;
    for (int k = 0; k < kDim; ++k) {
      if (k != worst && !(c.mean_p(k) < alpha_test)) continue;
      words.push_back(c.name + ": " + kComponent[k] + " mean " + num(c.measured.mean(k)) + " " +
                      kUnit[k] + ", " + num(std::abs(c.mean_t(k)), "%.1f") +
                      " standard errors from the predicted " + num(c.predicted_mean(k)));
    }
  }
  if (c.cov_test.valid && c.cov_test.p_value < alpha_test) {
    bool named = false;
    for (int k = 0; k < kDim; ++k) {
      if (!(c.variance_p(k) < alpha_test)) continue;
      words.push_back(c.name + ": " + kComponent[k] + " variance " +
                      num(c.variance_ratio(k), "%.2g") + "x predicted");
      named = true;
    }
    if (!named) {
      double worst = -1;
      std::string text;
      for (int a = 0; a < kDim; ++a) {
        for (int b = a + 1; b < kDim; ++b) {
          const double rm = c.measured.cov(a, b) / std::sqrt(c.measured.cov(a, a) * c.measured.cov(b, b));
          const double rp = c.predicted_cov(a, b) /
                            std::sqrt(c.predicted_cov(a, a) * c.predicted_cov(b, b));
          if (std::abs(rm - rp) > worst) {
            worst = std::abs(rm - rp);
            text = c.name + ": " + kComponent[a] + "-" + kComponent[b] + " correlation " +
                   num(rm, "%.2f") + " measured against " + num(rp, "%.2f") + " predicted";
          }
        }
      }
      if (c.cov_method == "nees") {
        text = c.name + ": errors " + num(std::sqrt(c.nees_mean / kDim), "%.2g") +
               "x the predicted spread (NEES " + num(c.nees_mean, "%.3g") +
               " per run against 3)";
      }
      words.push_back(text);
    }
  }
  return words;
}

}  // namespace

SuiteModel suite_model(const Suite& suite) {
  return {suite.robot, suite.model_effects, suite.measurement_noise};
}

std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model) {
  const double B = model.robot.wheelbase_m;
  const Matrix3 meas = model.measurement_noise.covariance();
  std::vector<std::vector<RunResidual>> out(suite.experiments.size());
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    out[e].resize(ex.runs.size());
    if (!ex.logged) {
      const Prediction p = predict(model_pieces(ex.path, B), model.robot, model.effects);
      const Vector3 odometry = B == suite.robot.wheelbase_m && !ex.runs.empty()
                                   ? ex.runs.front().odometry
                                   : sampled_end_pose(ex.path, B);
      for (std::size_t r = 0; r < ex.runs.size(); ++r) {
        out[e][r] = {error_against(ex.runs[r].measured, odometry), p.mean + p.noise_mean,
                     p.cov + meas};
      }
      continue;
    }
    tbb::parallel_for(std::size_t{0}, ex.runs.size(), [&](std::size_t r) {
      const Prediction p = predict(ex.runs[r].pieces, model.robot, model.effects);
      out[e][r] = {error_against(ex.runs[r].measured, p.odometry_end_pose), p.mean + p.noise_mean,
                   p.cov + meas};
    });
  }
  return out;
}

double log_likelihood(const std::vector<std::vector<RunResidual>>& res) {
  double sum = 0.0;
  for (const auto& ex : res) {
    for (const RunResidual& r : ex) sum += gaussian_log_density(r.error, r.mean, r.cov);
  }
  return sum;
}

Comparison compare(const Suite& suite, const SuiteModel& model, double alpha) {
  Comparison out;
  out.alpha = alpha;
  out.alpha_per_test = alpha / static_cast<double>(2 * suite.experiments.size() + 1);
  const auto res = residuals(suite, model);
  std::vector<Vector3> pooled;  // whitened residuals, centred per experiment
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    std::vector<Vector3> z;
    out.experiments.push_back(
        compare_experiment(suite.experiments[e], res[e], out.alpha_per_test, z));
    out.log_likelihood += out.experiments.back().log_likelihood;
    Vector3 mean = Vector3::Zero();
    for (const Vector3& v : z) mean += v / static_cast<double>(z.size());
    for (const Vector3& v : z) pooled.push_back(v - mean);
  }
  // Mardia's multivariate kurtosis [Mardia70] of the pooled residuals against their own
  // covariance (so it tests shape, not scale): b2 = mean((d' S^-1 d)^2), E b2 = p(p+2)(N-1)/(N+1)
  // and Var b2 = 8p(p+2)/N under normality.
  const double N = static_cast<double>(pooled.size());
  if (pooled.size() > 2 * kDim) {
    Matrix3 S = Matrix3::Zero();
    for (const Vector3& d : pooled) S += d * d.transpose() / N;
    const Eigen::LLT<Matrix3> llt(S);
    for (const Vector3& d : pooled) {
      const double m = d.dot(llt.solve(d));
      out.mardia_b2 += m * m / N;
    }
    const double expected = kDim * (kDim + 2) * (N - 1) / (N + 1);
    out.kurtosis.statistic = (out.mardia_b2 - expected) / std::sqrt(8.0 * kDim * (kDim + 2) / N);
    out.kurtosis.dof = 0;
    out.kurtosis.p_value = 2.0 * boost::math::cdf(boost::math::complement(
                                     boost::math::normal(), std::abs(out.kurtosis.statistic)));
  } else {
    out.kurtosis.valid = false;
  }

  std::vector<const ExperimentComparison*> order;
  for (const auto& c : out.experiments) order.push_back(&c);
  auto worst_p = [](const ExperimentComparison* c) {
    return std::min(c->mean_test.valid ? c->mean_test.p_value : 1.0,
                    c->cov_test.valid ? c->cov_test.p_value : 1.0);
  };
  // Worst first: smallest p-value, ties (p underflowing to 0) broken by the NEES per run.
  std::stable_sort(order.begin(), order.end(), [&](auto* a, auto* b) {
    return worst_p(a) != worst_p(b) ? worst_p(a) < worst_p(b) : a->nees_mean > b->nees_mean;
  });
  bool inconsistent = false;
  for (const ExperimentComparison* c : order) {
    inconsistent = inconsistent || c->verdict == "inconsistent";
    for (std::string& w : failure_words(*c, out.alpha_per_test)) out.failures.push_back(std::move(w));
  }
  if (out.kurtosis.valid && out.kurtosis.p_value < out.alpha_per_test) {
    inconsistent = true;
    const double expected = kDim * (kDim + 2) * (N - 1) / (N + 1);
    out.failures.push_back(std::string(out.mardia_b2 > expected ? "tails heavier" : "tails lighter") +
                           " than Gaussian: Mardia kurtosis " + num(out.mardia_b2, "%.1f") +
                           " against " + num(expected, "%.1f") + ", p = " +
                           num(out.kurtosis.p_value, "%.2g"));
  }
  out.verdict = inconsistent ? "inconsistent" : "consistent";
  return out;
}

}  // namespace odomcov
