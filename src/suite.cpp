#include "odomcov/suite.hpp"

#include <tbb/parallel_for.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <limits>
#include <filesystem>
#include <set>

#include "csv.hpp"
#include "odomcov/config.hpp"
#include "odomcov/format.hpp"
#include "odomcov/propagation.hpp"
#include "yaml_util.hpp"

namespace odomcov {
namespace {

using yaml::Where;


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
    runs.push_back(std::move(run));
  }
  return runs;
}

SuiteRun load_log(const std::string& log_file, double wheelbase_m) {
  const csv::Table table = csv::read(log_file, {"t", "left", "right", "x", "y", "theta"});
  SuiteRun run;
  run.id = std::filesystem::path(log_file).stem().string();
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
  return run;
}

}  // namespace

MeasurementNoise parse_measurement_noise(const YAML::Node& node, const std::string& file,
                                         const std::string& key) {
  const Where where{file, key};
  yaml::require_map(where, node, {"xy", "theta_deg"});
  MeasurementNoise m;
  m.xy_m = yaml::optional_number(where, node, "xy").value_or(0.0);
  m.theta_rad = yaml::optional_number(where, node, "theta_deg").value_or(0.0) * kDegToRad;
  if (m.xy_m < 0) yaml::fail(where.child("xy"), node["xy"], "must be >= 0");
  if (m.theta_rad < 0) yaml::fail(where.child("theta_deg"), node["theta_deg"], "must be >= 0");
  return m;
}

Matrix3 MeasurementNoise::covariance() const {
  return Vector3(xy_m * xy_m, xy_m * xy_m, theta_rad * theta_rad).asDiagonal();
}

Vector3 SuiteRun::error() const { return pose_error(measured, odometry); }

Vector3 sampled_end_pose(const Path& path, double wheelbase_m) {
  Vector3 pose = Vector3::Zero();
  for (const SampleRun& run : sample_schedule(path)) {
    const double n = static_cast<double>(run.count);
    // `count` samples of one increment lie on one arc: drive it in one step.
    pose = drive(pose, {n * run.increment.left_m, n * run.increment.right_m}, wheelbase_m);
  }
  return pose;
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
    suite.measurement_noise = parse_measurement_noise(noise, file, "measurement_noise");
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

double student_t_two_sided(double t, double dof) {
  if (!(dof > 0) || !std::isfinite(t)) return std::isfinite(t) ? 1.0 : 0.0;
  return 2.0 * boost::math::cdf(boost::math::complement(boost::math::students_t(dof), std::abs(t)));
}

double chi2_two_sided(double x, double dof) {
  const boost::math::chi_squared d(dof);
  const double lower = boost::math::cdf(d, std::max(x, 0.0));
  return std::min(1.0, 2.0 * std::min(lower, 1.0 - lower));
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
  c.errors = std::move(errors);
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
      words.push_back(c.name + ": " + kComponent[k] + " mean " + format_number(c.measured.mean(k), "%.4g") + " " +
                      kUnit[k] + ", " + format_number(std::abs(c.mean_t(k)), "%.1f") +
                      " standard errors from the predicted " + format_number(c.predicted_mean(k), "%.4g"));
    }
  }
  if (c.cov_test.valid && c.cov_test.p_value < alpha_test) {
    bool named = false;
    for (int k = 0; k < kDim; ++k) {
      if (!(c.variance_p(k) < alpha_test)) continue;
      words.push_back(c.name + ": " + kComponent[k] + " variance " +
                      format_number(c.variance_ratio(k), "%.2g") + "x predicted");
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
                   format_number(rm, "%.2f") + " measured against " + format_number(rp, "%.2f") + " predicted";
          }
        }
      }
      if (c.cov_method == "nees") {
        text = c.name + ": errors " + format_number(std::sqrt(c.nees_mean / kDim), "%.2g") +
               "x the predicted spread (NEES " + format_number(c.nees_mean, "%.3g") +
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

std::string robot_yaml(const Robot& robot) {
  return "robot: {wheelbase: " + format_number(robot.wheelbase_m) + ", k_left: " +
         format_number(robot.noise.k_left) + ", k_right: " + format_number(robot.noise.k_right) + "}";
}

std::string model_yaml(const SuiteModel& model) {
  std::string text = robot_yaml(model.robot) + "\n";
  if (!model.effects.empty()) {
    text += "model:\n  effects:\n";
    for (const EffectSpec& e : model.effects) text += "    " + effect_yaml(e) + "\n";
  }
  return text;
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
        out[e][r] = {pose_error(ex.runs[r].measured, odometry), p.mean + p.noise_mean,
                     p.cov + meas};
      }
      continue;
    }
    tbb::parallel_for(std::size_t{0}, ex.runs.size(), [&](std::size_t r) {
      const Prediction p = predict(ex.runs[r].pieces, model.robot, model.effects);
      out[e][r] = {pose_error(ex.runs[r].measured, p.odometry_end_pose), p.mean + p.noise_mean,
                   p.cov + meas};
    });
  }
  return out;
}

std::vector<double> run_log_likelihoods(const std::vector<std::vector<RunResidual>>& res,
                                        bool scatter) {
  std::vector<double> out;
  for (const auto& ex : res) {
    const double n = static_cast<double>(ex.size());
    if (!scatter) {
      for (const RunResidual& r : ex) out.push_back(gaussian_log_density(r.error, r.mean, r.cov));
      continue;
    }
    Vector3 mean = Vector3::Zero();
    for (const RunResidual& r : ex) mean += (r.error - r.mean) / n;
    for (const RunResidual& r : ex) {
      const Eigen::LLT<Matrix3> llt(r.cov);
      if (ex.size() < 2) {
        out.push_back(0.0);  // a lone run says nothing about the spread
      } else if (llt.info() != Eigen::Success) {
        out.push_back(-std::numeric_limits<double>::infinity());
      } else {
        const Vector3 d = r.error - r.mean - mean;
        const Eigen::Matrix3d L = llt.matrixL();
        const double log_det = 2.0 * L.diagonal().array().log().sum() + kDim * std::log(2.0 * M_PI);
        out.push_back(-0.5 * d.dot(llt.solve(d)) - 0.5 * (n - 1) / n * log_det);
      }
    }
  }
  return out;
}

double log_likelihood(const std::vector<std::vector<RunResidual>>& res) {
  double sum = 0.0;
  for (double v : run_log_likelihoods(res, false)) sum += v;
  return sum;
}

double scatter_log_likelihood(const std::vector<std::vector<RunResidual>>& res) {
  double sum = 0.0;
  for (double v : run_log_likelihoods(res, true)) sum += v;
  return sum;
}

Comparison compare(const Suite& suite, const SuiteModel& model, double alpha) {
  Comparison out;
  out.alpha = alpha;
  out.alpha_per_test = alpha / static_cast<double>(2 * suite.experiments.size() + 1);
  const auto res = residuals(suite, model);
  // Mardia's multivariate kurtosis [Mardia70] as a test of shape only: each experiment's
  // whitened residuals are standardised by that experiment's own mean and covariance (so scale
  // and mean misfits, which differ between experiments, do not read as tails), and the
  // experiments with at least kMinRunsForLrt runs are combined with Mardia's exact moments
  // [Mardia74]: E b2 = p(p+2)(n-1)/(n+1),
  // Var b2 = 8p(p+2)(n-3)(n-p-1)(n-p+1)/((n+1)^2 (n+3)(n+5)), z = sum n(b2 - E)/sqrt(sum n^2 Var).
  bool tails_expected = false;
  for (const EffectSpec& e : model.effects) tails_expected = tails_expected || find_effect(e.name)->heavy_tails;
  double excess = 0.0, variance = 0.0, weight = 0.0, b2_sum = 0.0;
  std::vector<double> kurtosis_ratio(suite.experiments.size(), 1.0);  // b2/E b2 per experiment
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    std::vector<Vector3> z;
    out.experiments.push_back(
        compare_experiment(suite.experiments[e], res[e], out.alpha_per_test, z));
    out.log_likelihood += out.experiments.back().log_likelihood;
    const double n = static_cast<double>(z.size());
    if (z.size() < static_cast<std::size_t>(kMinRunsForLrt)) continue;
    const SampleMoments m = moments(z);
    const Matrix3 S = m.cov * ((n - 1) / n);
    const Eigen::LLT<Matrix3> llt(S);
    double b2 = 0.0;
    for (const Vector3& v : z) {
      const double q = (v - m.mean).dot(llt.solve(v - m.mean));
      b2 += q * q / n;
    }
    constexpr double p = kDim;
    const double expected = p * (p + 2) * (n - 1) / (n + 1);
    const double var = 8 * p * (p + 2) * (n - 3) * (n - p - 1) * (n - p + 1) /
                       ((n + 1) * (n + 1) * (n + 3) * (n + 5));
    kurtosis_ratio[e] = b2 / expected;
    excess += n * (b2 - expected);
    variance += n * n * var;
    weight += n;
    b2_sum += n * b2;
    out.mardia_expected += n * expected;
  }
  if (weight > 0) {
    out.mardia_b2 = b2_sum / weight;
    out.mardia_expected /= weight;
    // A model with a heavy-tailed effect (bumps) predicts tails: then the kurtosis is
    // information, not a failure, and a Gaussian LRT's null distribution is wider by the
    // kurtosis factor 1 + kappa = b2/E b2, so each experiment's statistic is divided by its own
    // factor (the scaled test of [Browne84] for elliptical errors) before the verdicts. Its own:
    // a short experiment sees a bump or two per run and far heavier tails than a long one.
    if (tails_expected && out.mardia_b2 > out.mardia_expected) {
      out.kurtosis_scale = out.mardia_b2 / out.mardia_expected;
      for (std::size_t i = 0; i < out.experiments.size(); ++i) {
        ExperimentComparison& e = out.experiments[i];
        if (e.cov_method != "lrt" || !e.cov_test.valid) continue;
        e.cov_test.statistic /= std::max(1.0, kurtosis_ratio[i]);
        e.cov_test.p_value = chi2_sf(e.cov_test.statistic, e.cov_test.dof);
        e.cov_method = "lrt, kurtosis-scaled";
        const bool reject = (e.mean_test.valid && e.mean_test.p_value < out.alpha_per_test) ||
                            e.cov_test.p_value < out.alpha_per_test;
        e.verdict = reject ? "inconsistent" : "consistent";
      }
    }
    out.kurtosis.statistic = excess / std::sqrt(variance);
    out.kurtosis.dof = 0;
    out.kurtosis.p_value = 2.0 * boost::math::cdf(boost::math::complement(
                                     boost::math::normal(), std::abs(out.kurtosis.statistic)));
  } else {
    out.kurtosis.valid = false;  // no experiment is large enough to tell a shape
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
  if (out.kurtosis.valid && out.kurtosis.p_value < out.alpha_per_test && !tails_expected) {
    inconsistent = true;
    out.failures.push_back(std::string(out.kurtosis.statistic > 0 ? "tails heavier" : "tails lighter") +
                           " than Gaussian: Mardia kurtosis " + format_number(out.mardia_b2, "%.1f") +
                           " against " + format_number(out.mardia_expected, "%.1f") + ", p = " +
                           format_number(out.kurtosis.p_value, "%.2g"));
  }
  out.verdict = inconsistent ? "inconsistent" : "consistent";
  return out;
}

}  // namespace odomcov
