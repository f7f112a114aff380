#include "odomcov/measurement/residual_features.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <algorithm>
#include <boost/math/distributions/fisher_f.hpp>
#include <cmath>
#include <map>

namespace odomcov {
namespace {

constexpr int kDim = 3;
/// A wheel's direction counts as reversed once it has moved this far back from its furthest
/// point: encoder jitter of a tick or two on a standing wheel is not a reversal.
constexpr double kReversalHysteresis_m = 0.005;

/// Accumulates the features piece by piece.
class FeatureAccumulator {
 public:
  explicit FeatureAccumulator(double wheelbase_m) : B_(wheelbase_m) {}

  void add(const ArcSegment& piece, double duration_s) {
    const double travel = 0.5 * (std::abs(piece.left_m) + std::abs(piece.right_m));
    const double dtheta = (piece.right_m - piece.left_m) / B_;
    f_.distance_m += travel;
    f_.duration_s += duration_s;
    f_.angle_turned_rad += dtheta;
    abs_turn_ += std::abs(dtheta);
    spin_ += std::abs(piece.right_m - piece.left_m);
    const double centre = piece.center_m();
    signed_centre_ += centre;
    abs_centre_ += std::abs(centre);
    if (duration_s > 0 && travel > 0) speed_weighted_ += travel * travel / duration_s;
    track(left_, piece.left_m);
    track(right_, piece.right_m);
  }

  PathFeatures result() const {
    PathFeatures f = f_;
    f.turn_direction = abs_turn_ > 0 ? f.angle_turned_rad / abs_turn_ : 0.0;
    f.spin_fraction = f.distance_m > 0 ? spin_ / (2.0 * f.distance_m) : 0.0;
    f.travel_direction = abs_centre_ > 0 ? signed_centre_ / abs_centre_ : 0.0;
    f.reversals = left_.reversals + right_.reversals;
    f.speed_mps = f.distance_m > 0 ? speed_weighted_ / f.distance_m : 0.0;
    return f;
  }

 private:
  struct Wheel {
    double position = 0.0, extreme = 0.0;
    int direction = 0;  // +1, -1, 0 before it has moved kReversalHysteresis_m
    int reversals = 0;
  };
  static void track(Wheel& w, double increment) {
    w.position += increment;
    if (w.direction == 0) {
      if (std::abs(w.position) >= kReversalHysteresis_m) {
        w.direction = w.position > 0 ? 1 : -1;
        w.extreme = w.position;
      }
      return;
    }
    if ((w.position - w.extreme) * w.direction > 0) {
      w.extreme = w.position;
    } else if (std::abs(w.position - w.extreme) >= kReversalHysteresis_m) {
      ++w.reversals;
      w.direction = -w.direction;
      w.extreme = w.position;
    }
  }

  double B_;
  PathFeatures f_;
  double abs_turn_ = 0, spin_ = 0, signed_centre_ = 0, abs_centre_ = 0, speed_weighted_ = 0;
  Wheel left_, right_;
};

double feature_value(const PathFeatures& f, const std::string& name) {
  if (name == "distance") return f.distance_m;
  if (name == "angle_turned") return f.angle_turned_rad;
  if (name == "turn_direction") return f.turn_direction;
  if (name == "spin_fraction") return f.spin_fraction;
  if (name == "travel_direction") return f.travel_direction;
  if (name == "reversals") return f.reversals;
  return f.speed_mps;  // "speed"
}

std::string description(const std::string& feature) {
  if (feature == "distance") {
    return "an error that grows with the distance driven: a scale error (scale_error) or unequal "
           "wheel diameters (wheel_diameter_ratio) in the catalogue; when those are already in the "
           "model, a scale that changes along the run (wear, tyre heating), which is in no "
           "catalogue: a custom effect such as scale: 1 + a*s would model it";
  }
  if (feature == "angle_turned") {
    return "an error that grows with the signed angle turned: a wrong effective wheelbase "
           "(wheelbase_error); when that is in the model, a wheelbase that depends on how the "
           "robot turns (turn_dependent_wheelbase, or a custom wheelbase_factor in kappa or r)";
  }
  if (feature == "turn_direction") {
    return "an error that depends on the direction of the turns, not only on how much was turned: "
           "left and right turns with different effective wheelbases or slip; not in the "
           "catalogue: a custom effect such as wheelbase_factor: 1 + a*turn would model it";
  }
  if (feature == "spin_fraction") {
    return "an error that depends on how tightly the robot turns (spins against arcs against "
           "lines): tyre scrub that moves the effective contact points with the kind of turn "
           "(turn_dependent_wheelbase; or a custom wheelbase_factor: 1 + a*r)";
  }
  if (feature == "travel_direction") {
    return "an error that differs forwards and backwards: a scale or wheel diameter ratio that "
           "depends on the direction of travel; not in the catalogue: a custom effect such as "
           "scale: 1 + a*dir would model it (or backlash, when the runs reverse)";
  }
  if (feature == "reversals") {
    return "an error that grows with the number of times a wheel reverses: lost motion at each "
           "reversal, as play in the gears gives (backlash)";
  }
  if (feature == "speed") {
    return "a scale or slip that grows with speed: not in the catalogue; a custom effect such as "
           "scale: 1 + a*(v - v0) would model it";
  }
  return "an error that differs between groups (sessions, days, floors) more than the model "
         "allows: a parameter that changes from group to group, e.g. tyre pressure or floor "
         "(group_variation)";
}

/// Each experiment's mean residual in the end frame and its predicted covariance (inverted).
struct ExperimentMean {
  Vector3 r = Vector3::Zero();
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();  // d r / d (Es, Eb, Ed), columns, end frame
  Matrix3 W = Matrix3::Zero();  // C^-1
  PathFeatures features;
  std::string group;
};

/// RSS of the GLS fit of r_e = X_e b over the experiments.
double gls_rss(const std::vector<ExperimentMean>& ms, const std::vector<Eigen::MatrixXd>& X) {
  const Eigen::Index p = X.front().cols();
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(p, p);
  Eigen::VectorXd c = Eigen::VectorXd::Zero(p);
  for (std::size_t e = 0; e < ms.size(); ++e) {
    A += X[e].transpose() * ms[e].W * X[e];
    c += X[e].transpose() * ms[e].W * ms[e].r;
  }
  const Eigen::VectorXd b = A.completeOrthogonalDecomposition().solve(c);
  double rss = 0.0;
  for (std::size_t e = 0; e < ms.size(); ++e) {
    const Vector3 d = ms[e].r - X[e] * b;
    rss += d.dot(ms[e].W * d);
  }
  return rss;
}

/// F test of the nested designs X1 (H1) against X0 (H0).
void f_test(const std::vector<ExperimentMean>& ms, const std::vector<Eigen::MatrixXd>& X0,
            const std::vector<Eigen::MatrixXd>& X1, ResidualAlignment& out) {
  const int m = static_cast<int>(ms.size());
  const int p1 = static_cast<int>(X1.front().cols()), p0 = static_cast<int>(X0.front().cols());
  out.dof1 = p1 - p0;
  out.dof2 = kDim * m - p1;
  if (out.dof1 <= 0 || out.dof2 <= 0) return;
  const double rss0 = gls_rss(ms, X0), rss1 = gls_rss(ms, X1);
  if (!(rss1 > 0) || !std::isfinite(rss0)) return;
  out.statistic = std::max(0.0, (rss0 - rss1) / out.dof1) / (rss1 / out.dof2);
  out.p_value_raw = boost::math::cdf(
      boost::math::complement(boost::math::fisher_f(out.dof1, out.dof2), out.statistic));
  out.testable = true;
}

/// The systematic directions a feature can modulate: the wheel scale, the wheelbase and the
/// wheel diameter ratio (the catalogue's factor parameters, neutral at 1).
const char* const kDirections[] = {"scale_error", "wheelbase_error", "wheel_diameter_ratio"};
constexpr double kSensitivityStep = 1e-4;

/// The model with one factor effect moved by kSensitivityStep (added at 1 + step if absent).
SuiteModel nudged(const SuiteModel& model, const std::string& effect) {
  SuiteModel m = model;
  if (EffectSpec* e = find_spec(m.effects, effect)) {
    e->values[0] += kSensitivityStep;
    return m;
  }
  m.effects.push_back({effect, {1.0 + kSensitivityStep}});
  return m;
}

using Residuals = std::vector<std::vector<RunResidual>>;

/// The rotation from the world frame into a run's odometry end frame (along-track,
/// cross-track, heading) at end heading `heading` [rad].
Matrix3 end_frame(double heading) {
  Matrix3 R = Matrix3::Identity();
  R.topLeftCorner<2, 2>() << std::cos(heading), std::sin(heading), -std::sin(heading), std::cos(heading);
  return R;
}

/// Adds a run's path features, each divided by the experiment's run count `n`, to `sum`.
void add_features(PathFeatures& sum, const PathFeatures& f, double n) {
  sum.distance_m += f.distance_m / n;
  sum.angle_turned_rad += f.angle_turned_rad / n;
  sum.turn_direction += f.turn_direction / n;
  sum.spin_fraction += f.spin_fraction / n;
  sum.travel_direction += f.travel_direction / n;
  sum.reversals += f.reversals / n;
  sum.speed_mps += f.speed_mps / n;
}

/// Experiment e's mean residual, its sensitivities to the factor directions (from the nudged
/// models' residuals `nudges`) and its covariance, all in the runs' end frames, with its mean
/// features and group. False when the covariance is not positive definite (no test can use
/// the experiment).
bool experiment_mean(const SuiteExperiment& ex, std::size_t e, const Residuals& residuals,
                     const std::vector<Residuals>& nudges, double B, ExperimentMean& m) {
  const double n = static_cast<double>(ex.runs.size());
  Matrix3 C = Matrix3::Zero();
  PathFeatures sum;
  for (std::size_t r = 0; r < ex.runs.size(); ++r) {
    const Matrix3 R = end_frame(odometry_end_pose(ex, ex.runs[r], B).z());
    const RunResidual& res = residuals[e][r];
    m.r += R * (res.error - res.mean) / n;
    for (int j = 0; j < kDim; ++j) {
      m.S.col(j) += R * (nudges[static_cast<std::size_t>(j)][e][r].mean - res.mean) / (kSensitivityStep * n);
    }
    C += R * res.cov * R.transpose() / (n * n);
    add_features(sum, path_features(ex, ex.runs[r], B), n);
  }
  const Eigen::LDLT<Matrix3> ldlt(C);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return false;
  m.W = ldlt.solve(Matrix3::Identity());
  m.features = sum;
  m.group = experiment_group(ex);
  return true;
}

/// The means of every experiment with runs and a usable covariance.
std::vector<ExperimentMean> experiment_means(const Suite& suite, const SuiteModel& model,
                                             const Residuals& residuals) {
  const double B = model.robot.wheelbase_m;
  // First-order sensitivity of every run's predicted mean to each factor direction.
  std::vector<Residuals> nudges;
  for (const char* effect : kDirections) nudges.push_back(odomcov::residuals(suite, nudged(model, effect)));
  std::vector<ExperimentMean> ms;
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    if (ex.runs.empty()) continue;
    ExperimentMean m;
    if (experiment_mean(ex, e, residuals, nudges, B, m)) ms.push_back(std::move(m));
  }
  return ms;
}

/// H1 of a path feature: the base design X0 plus the same terms modulated by the feature,
/// centred and scaled (the fit does not depend on it, its conditioning does); F test against
/// X0, untestable when the feature does not vary across the experiments.
void feature_test(const std::vector<ExperimentMean>& ms, const std::vector<Eigen::MatrixXd>& X0,
                  const std::string& name, ResidualAlignment& a) {
  double mean = 0, spread = 0;
  for (const ExperimentMean& m : ms) mean += feature_value(m.features, name) / static_cast<double>(ms.size());
  for (const ExperimentMean& m : ms) spread = std::max(spread, std::abs(feature_value(m.features, name) - mean));
  if (!(spread > 1e-9 * std::max(1.0, std::abs(mean)))) return;
  std::vector<Eigen::MatrixXd> X1;
  for (std::size_t e = 0; e < ms.size(); ++e) {
    const double f = (feature_value(ms[e].features, name) - mean) / spread;
    Eigen::MatrixXd x(kDim, 4 * kDim);
    x << X0[e], f * X0[e];
    X1.push_back(x);
  }
  f_test(ms, X0, X1, a);
}

/// One-way ANOVA of the groups: the base terms per group against common ones; untestable with
/// fewer than two groups.
void group_test(const std::vector<ExperimentMean>& ms, const std::vector<Eigen::MatrixXd>& X0,
                ResidualAlignment& a) {
  std::map<std::string, int> index;
  for (const ExperimentMean& m : ms) index.emplace(m.group, static_cast<int>(index.size()));
  const auto groups = static_cast<Eigen::Index>(index.size());
  if (groups < 2) return;
  std::vector<Eigen::MatrixXd> X1;
  for (std::size_t e = 0; e < ms.size(); ++e) {
    Eigen::MatrixXd x = Eigen::MatrixXd::Zero(kDim, 2 * kDim * groups);
    x.middleCols(2 * kDim * index.at(ms[e].group), 2 * kDim) = X0[e];
    X1.push_back(x);
  }
  f_test(ms, X0, X1, a);
}

/// Family-wise p-values (Bonferroni over the testable features), then testable features
/// first, each by raw p-value.
void adjust_and_rank(std::vector<ResidualAlignment>& out) {
  int tests = 0;
  for (const ResidualAlignment& a : out) tests += a.testable ? 1 : 0;
  for (ResidualAlignment& a : out) {
    a.p_value = a.testable ? std::min(1.0, a.p_value_raw * tests) : 1.0;
  }
  std::stable_sort(out.begin(), out.end(), [](const ResidualAlignment& x, const ResidualAlignment& y) {
    if (x.testable != y.testable) return x.testable;
    return x.p_value_raw < y.p_value_raw;
  });
}

}  // namespace

PathFeatures path_features(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m) {
  FeatureAccumulator acc(wheelbase_m);
  if (ex.logged) {
    for (std::size_t i = 0; i < run.pieces.size(); ++i) {
      acc.add(run.pieces[i], i < run.durations_s.size() ? run.durations_s[i] : 0.0);
    }
  } else {
    for (std::size_t i = 0; i < ex.path.interval_count(); ++i) {
      acc.add(ex.path.interval(i), ex.path.keyframes[i + 1].t_s - ex.path.keyframes[i].t_s);
    }
  }
  return acc.result();
}

std::string experiment_group(const SuiteExperiment& ex) { return group_key(ex); }

const std::vector<std::string>& residual_feature_names() {
  static const std::vector<std::string> names = {"distance",         "angle_turned", "turn_direction",
                                                 "spin_fraction",    "travel_direction",
                                                 "reversals",        "speed",        "group"};
  return names;
}

std::vector<ResidualAlignment> residual_alignment(
    const Suite& suite, const SuiteModel& model,
    const std::vector<std::vector<RunResidual>>& residuals) {
  const std::vector<ExperimentMean> ms = experiment_means(suite, model, residuals);
  // H0: the misfit is a constant offset in the end frame plus constant factor errors,
  // r_e = [I3 S_e] c. H1 adds the same terms modulated by the feature, f_e [I3 S_e] d: a
  // scale, wheelbase or diameter ratio (or an offset) that varies with the feature.
  std::vector<Eigen::MatrixXd> X0;
  for (const ExperimentMean& m : ms) {
    Eigen::MatrixXd x(kDim, 2 * kDim);
    x << Matrix3::Identity(), m.S;
    X0.push_back(x);
  }
  std::vector<ResidualAlignment> out;
  for (const std::string& name : residual_feature_names()) {
    ResidualAlignment a;
    a.feature = name;
    a.description = description(name);
    if (!ms.empty() && name != "group") {
      feature_test(ms, X0, name, a);
    } else if (!ms.empty()) {
      group_test(ms, X0, a);
    }
    out.push_back(std::move(a));
  }
  adjust_and_rank(out);
  return out;
}

}  // namespace odomcov
