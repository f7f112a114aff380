#include "odomcov/measurement/residual_features.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <cmath>
#include <limits>
#include <map>
#include <optional>

#include "odomcov/effects/effects.hpp"
#include "odomcov/measurement/referee.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;
/// The systematic directions a feature can modulate (directions() below): the three factor
/// effects and a sideways slip.
constexpr int kDirectionCount = 4;
/// The start frame's two position axes: an offset fixed in each run's start frame.
constexpr int kStartFrameTerms = 2;
/// The mean part's base terms per experiment: a constant offset in the end frame and one in the
/// start frame, and the directions.
constexpr int kBaseTerms = kDim + kStartFrameTerms + kDirectionCount;
/// The terms a feature modulates: a heading offset, an offset in the start frame and the
/// directions; not the end frame's position offset, the constant a marker off the axle centre
/// adds. Varying it too costs power: on the open batch 29012028 three of the four worlds whose
/// scale fades lost distance as their first feature with it, one without it.
constexpr int kModulatedTerms = 1 + kStartFrameTerms + kDirectionCount;
/// A wheel's direction counts as reversed once it has moved this far back from its furthest
/// point: encoder jitter of a tick or two on a standing wheel is not a reversal.
constexpr double kReversalHysteresis_m = 0.005;
/// sin(x)/x; below this |x| its Taylor series 1 - x^2/6 (the next term, x^4/120, is below 1e-18
/// there, under rounding), with no jump at the switch.
constexpr double kSincSeriesBelow = 1e-4;

double sinc(double x) { return std::abs(x) < kSincSeriesBelow ? 1.0 - x * x / 6.0 : std::sin(x) / x; }

/// Accumulates the features piece by piece.
class FeatureAccumulator {
 public:
  /// `heading0_rad`: the run's start heading in the reference's frame.
  FeatureAccumulator(double wheelbase_m, double heading0_rad) : B_(wheelbase_m), heading_(heading0_rad) {}

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
    if (duration_s > 0) {
      swing(left_speed_, piece.left_m / duration_s);
      swing(right_speed_, piece.right_m / duration_s);
    }
    track(left_, piece.left_m);
    track(right_, piece.right_m);
    // The mean of (cos, sin) of a heading turning linearly by dtheta over the piece:
    // (cos, sin)(mid) sinc(dtheta/2), weighted by the travel.
    const double mid = heading_ + 0.5 * dtheta, weight = travel * sinc(0.5 * dtheta);
    heading_cos_ += weight * std::cos(mid);
    heading_sin_ += weight * std::sin(mid);
    heading_ += dtheta;
  }

  PathFeatures result() const {
    PathFeatures f = f_;
    f.turn_direction = abs_turn_ > 0 ? f.angle_turned_rad / abs_turn_ : 0.0;
    f.spin_fraction = f.distance_m > 0 ? spin_ / (2.0 * f.distance_m) : 0.0;
    f.travel_direction = abs_centre_ > 0 ? signed_centre_ / abs_centre_ : 0.0;
    f.reversals = left_.reversals + right_.reversals;
    f.speed_mps = f.distance_m > 0 ? speed_weighted_ / f.distance_m : 0.0;
    f.acceleration_mps = 0.5 * (finished(left_speed_) + finished(right_speed_));
    f.heading_cos = f.distance_m > 0 ? heading_cos_ / f.distance_m : 0.0;
    f.heading_sin = f.distance_m > 0 ? heading_sin_ / f.distance_m : 0.0;
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

  /// A wheel's speed as a zig-zag between turning points at least kAccelerationHysteresis_mps
  /// apart, from standstill: `total` sums the swings completed so far.
  struct Swing {
    double anchor = 0.0, extreme = 0.0, total = 0.0;
    int direction = 0;
  };
  static void swing(Swing& w, double speed) {
    if (w.direction == 0) {
      if (std::abs(speed - w.anchor) >= kAccelerationHysteresis_mps) {
        w.direction = speed > w.anchor ? 1 : -1;
        w.extreme = speed;
      }
      return;
    }
    if ((speed - w.extreme) * w.direction > 0) {
      w.extreme = speed;
    } else if (std::abs(speed - w.extreme) >= kAccelerationHysteresis_mps) {
      w.total += std::abs(w.extreme - w.anchor);
      w.anchor = w.extreme;
      w.extreme = speed;
      w.direction = -w.direction;
    }
  }
  /// The total with the stop at the end (back to standstill).
  static double finished(Swing w) {
    swing(w, 0.0);
    return w.total + (w.direction != 0 ? std::abs(w.extreme - w.anchor) : 0.0);
  }

  double B_;
  double heading_;  // absolute heading at the start of the next piece [rad]
  double heading_cos_ = 0, heading_sin_ = 0;
  PathFeatures f_;
  double abs_turn_ = 0, spin_ = 0, signed_centre_ = 0, abs_centre_ = 0, speed_weighted_ = 0;
  Wheel left_, right_;
  Swing left_speed_, right_speed_;
};

/// A residual feature: its value(s) for a run (two columns for the heading's direction), and
/// what a misfit along it points at, in the mean and in the scatter. `columns` 0: the groups'
/// one-way ANOVA. `needs_heading`: testable only when every run's start heading is known.
/// `run`: what a misfit along it run by run points at, for a feature in which the runs of one
/// experiment differ by design (their start headings; run_feature_test); null for the others.
/// The one table every list of features comes from.
struct Feature {
  const char* name;
  int columns;
  double (*value)(const PathFeatures& f, int column);
  const char* mean;
  const char* scatter;
  bool needs_heading = false;
  const char* run = nullptr;
};

const std::vector<Feature>& features() {
  static const std::vector<Feature> table = {
      {"distance", 1, [](const PathFeatures& f, int) { return f.distance_m; },
       "an error that grows with the distance driven: a scale error (scale_error) or unequal "
       "wheel diameters (wheel_diameter_ratio) in the catalogue; when those are already in the "
       "model, a scale that changes along the run (wear, tyre heating), which is in no "
       "catalogue: a custom effect such as scale: 1 + a*s would model it; or, where the runs "
       "start facing the same way, a floor that pushes every run the same way (a slope): an "
       "offset in the start frame that grows with the distance, in no catalogue; a custom "
       "effect such as lateral: \"b*cos(theta) - a*sin(theta)\" with scale: "
       "\"1 + a*cos(theta) + b*sin(theta)\" (theta the heading since the start) would model it",
       "a spread that grows with the distance driven faster than the model's: wheel radii that "
       "change from run to run (per_run_radius: variance as distance squared) or bumps; when the "
       "long runs alone are too noisy, a custom noise: \"1 + a*s\" would model it"},
      {"angle_turned", 1, [](const PathFeatures& f, int) { return f.angle_turned_rad; },
       "an error that grows with the signed angle turned: a wrong effective wheelbase "
       "(wheelbase_error); when that is in the model, a wheelbase that depends on how the "
       "robot turns (turn_dependent_wheelbase, or a custom wheelbase_factor in kappa or r)",
       "a spread that changes with the signed angle turned: heading noise that differs between "
       "left and right turns; slip on turns (turn_slip) when it grows with the turning either way"},
      {"turn_direction", 1, [](const PathFeatures& f, int) { return f.turn_direction; },
       "an error that depends on the direction of the turns, not only on how much was turned: "
       "left and right turns with different effective wheelbases or slip; not in the "
       "catalogue: a custom effect such as wheelbase_factor: 1 + a*turn would model it",
       "a spread that differs between left and right turns: slip that depends on the direction "
       "of the turn; a custom effect with noise: \"1 + a*(turn > 0)\" would model it"},
      {"spin_fraction", 1, [](const PathFeatures& f, int) { return f.spin_fraction; },
       "an error that depends on how tightly the robot turns (spins against arcs against "
       "lines): tyre scrub that moves the effective contact points with the kind of turn "
       "(turn_dependent_wheelbase; or a custom wheelbase_factor: 1 + a*r)",
       "extra noise on tight turns and spins: slip of the wheels as they scrub (turn_slip), or "
       "a custom noise: \"1 + a*r\""},
      {"travel_direction", 1, [](const PathFeatures& f, int) { return f.travel_direction; },
       "an error that differs forwards and backwards: a scale or wheel diameter ratio that "
       "depends on the direction of travel; not in the catalogue: a custom effect such as "
       "scale: 1 + a*dir would model it (or backlash, when the runs reverse)",
       "noise that differs forwards and backwards (a caster that shimmies one way): a custom "
       "noise: \"1 + a*(dir < 0)\" would model it"},
      {"reversals", 1, [](const PathFeatures& f, int) { return f.reversals; },
       "an error that grows with the number of times a wheel reverses: lost motion at each "
       "reversal, as play in the gears gives (backlash)",
       "a spread that grows with the number of reversals: play whose size varies from one "
       "reversal to the next, not the constant loss of backlash"},
      {"speed", 1, [](const PathFeatures& f, int) { return f.speed_mps; },
       "a scale or slip that grows with speed: not in the catalogue; a custom effect such as "
       "scale: 1 + a*(v - v0), or for a sideways slip lateral: a*v, would model it",
       "noise that grows with speed (slip and vibration at speed): not in the catalogue; a "
       "custom effect with noise: \"1 + a*v\", a factor on the wheel-noise variance, would "
       "model it"},
      {"acceleration", 1, [](const PathFeatures& f, int) { return f.acceleration_mps; },
       "an error that grows with the starts and stops (how much the wheels' speeds change): "
       "wheels that slip as they speed up or slow down and lose distance; a custom effect "
       "such as scale: \"1 - c*abs(a)\" (a the acceleration) would model it",
       "noise that grows with the starts and stops: random slip as the wheels speed up or slow "
       "down; a custom noise: \"1 + c*abs(a)\" would model it"},
      {"heading", 2,
       [](const PathFeatures& f, int column) { return column == 0 ? f.heading_cos : f.heading_sin; },
       "an error that depends on the direction the robot drives in the room (its absolute "
       "heading, from each run's heading0): a floor that slopes, down which the robot slides "
       "sideways, or a carpet or floorboards whose grain makes a wheel slip more one way; not in "
       "the catalogue: a custom effect such as lateral: \"a*cos(heading) + b*sin(heading)\" (a "
       "slope: sideways slip per metre) or scale: \"1 + a*cos(heading) + b*sin(heading)\" would "
       "model it",
       "a spread that depends on the direction the robot drives in the room: slip that is more "
       "random uphill than downhill, or across a carpet's grain than along it; a custom noise: "
       "\"exp(a*cos(heading) + b*sin(heading))\" would model it",
       true,
       "runs of one experiment that started at different headings end with errors that follow "
       "their heading: the spread between them is systematic, not noise, an error that depends on "
       "the direction the robot drives in the room (a floor that slopes, a carpet's grain); not "
       "in the catalogue: a custom effect such as lateral: \"a*cos(heading) + b*sin(heading)\" "
       "(sideways slip per metre) would model it"},
      {"group", 0, nullptr,
       "an error that differs between groups (sessions, days, floors) more than the model "
       "allows: a parameter that changes from group to group, e.g. tyre pressure or floor "
       "(group_variation)",
       "a spread that differs between groups (sessions, days, floors): noise that changes with "
       "the surface or the tyres; the noise level refitted per group, or a group's own noise"},
  };
  return table;
}

/// Each experiment's mean residual in the end frame and its predicted covariance (inverted),
/// and its spread about its own mean against the prediction (the scatter part).
struct ExperimentMean {
  Vector3 r = Vector3::Zero();
  // d r / d (Es, Eb, Ed, lateral slip), columns, end frame
  Eigen::Matrix<double, kDim, kDirectionCount> S = Eigen::Matrix<double, kDim, kDirectionCount>::Zero();
  // the start frame's x and y axes in the end frame (the runs' mean): what a unit offset fixed in
  // each run's start frame adds to r
  Eigen::Matrix<double, kDim, kStartFrameTerms> V = Eigen::Matrix<double, kDim, kStartFrameTerms>::Zero();
  Matrix3 W = Matrix3::Zero();  // C^-1
  PathFeatures features;
  std::string group;
  double scatter = 0.0;  // s_e = W_e / E[W_e]: 1 when the predicted spread is right
  double shape = 0.0;    // nu_e/2 = 3 (n - 1)/2, the gamma shape of s_e; 0: no scatter part
  double dispersion = 0.0;  // phi_e = shape * Var(s_e) in the model's simulated world; 0: unknown
  std::size_t experiment = 0;  // its index in the suite
  std::vector<Matrix3> frames, covs;  // each run's end frame and its covariance in it
  std::vector<Vector3> runs;          // each run's residual in its end frame
  std::vector<PathFeatures> run_features;
  bool headings_differ = false;  // its runs' start headings are known and not all the same
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

/// Columns of a design whose unit-length parts are dependent to this relative precision count
/// once (design_rank).
constexpr double kRankTolerance = 1e-9;

/// The F test's p-value and the alignment's fields, from the statistic and degrees of freedom.
void f_result(double statistic, int dof1, int dof2, ResidualAlignment& out) {
  out.dof1 = dof1;
  out.dof2 = dof2;
  out.statistic = statistic;
  out.p_value_raw = boost::math::cdf(
      boost::math::complement(boost::math::fisher_f(dof1, dof2), statistic));
  out.testable = true;
}

/// The rank of the designs X_e stacked over the experiments and whitened (C_e^-1/2 X_e), each
/// column scaled to unit length first: the number of terms the data can tell apart. (An offset
/// fixed in the start frame is one fixed in the end frame for a path that ends facing the way it
/// started; a suite of such paths alone cannot tell them apart.)
int design_rank(const std::vector<ExperimentMean>& ms, const std::vector<Eigen::MatrixXd>& X) {
  const Eigen::Index p = X.front().cols();
  Eigen::MatrixXd A(kDim * static_cast<Eigen::Index>(ms.size()), p);
  for (std::size_t e = 0; e < ms.size(); ++e) {
    const Eigen::LLT<Matrix3> llt(ms[e].W);  // W = L L^T: L^T X_e is the whitened design
    A.middleRows(kDim * static_cast<Eigen::Index>(e), kDim) = llt.matrixU() * X[e];
  }
  for (Eigen::Index j = 0; j < p; ++j) {
    const double norm = A.col(j).norm();
    if (norm > 0) A.col(j) /= norm;
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
  qr.setThreshold(kRankTolerance);
  return static_cast<int>(qr.rank());
}

/// The mean part's null design, shared by every feature's test: per experiment the base terms
/// X0 = [I3 V S] and the terms a feature modulates M = [e_theta V S] (alignment() says why), and
/// X0's rank and RSS, computed once.
struct MeanDesign {
  std::vector<Eigen::MatrixXd> base, modulated;
  int base_rank = 0;
  double base_rss = 0.0;
};

MeanDesign mean_design(const std::vector<ExperimentMean>& ms) {
  MeanDesign d;
  for (const ExperimentMean& m : ms) {
    Eigen::MatrixXd x(kDim, kBaseTerms);
    x << Matrix3::Identity(), m.V, m.S;
    d.base.push_back(x);
    Eigen::MatrixXd modulated(kDim, kModulatedTerms);
    modulated << Vector3::UnitZ(), m.V, m.S;
    d.modulated.push_back(modulated);
  }
  if (ms.empty()) return d;
  d.base_rank = design_rank(ms, d.base);
  d.base_rss = gls_rss(ms, d.base);
  return d;
}

/// F test of the nested design X1 (H1) against the null (H0), the degrees of freedom their ranks.
void f_test(const std::vector<ExperimentMean>& ms, const MeanDesign& null,
            const std::vector<Eigen::MatrixXd>& X1, ResidualAlignment& out) {
  const int m = static_cast<int>(ms.size());
  const int p1 = design_rank(ms, X1);
  out.dof1 = p1 - null.base_rank;
  out.dof2 = kDim * m - p1;
  if (out.dof1 <= 0 || out.dof2 <= 0) return;
  const double rss0 = null.base_rss, rss1 = gls_rss(ms, X1);
  if (!(rss1 > 0) || !std::isfinite(rss0)) return;
  f_result(std::max(0.0, (rss0 - rss1) / out.dof1) / (rss1 / out.dof2), out.dof1, out.dof2, out);
}

constexpr double kSensitivityStep = 1e-4;

/// The systematic directions a feature can modulate, each an effect at its neutral value: the
/// wheel scale, the wheelbase and the wheel diameter ratio (the catalogue's factor parameters,
/// neutral at 1), and a sideways slip of the centre per metre of wheel travel (a custom
/// `lateral: "a"`, neutral at 0: a floor's camber or a carpet's pile, in no catalogue, and no
/// combination of the factors). One definition of the custom for every model (the residual
/// cache keys a custom effect by its definition).
const std::array<EffectSpec, kDirectionCount>& directions() {
  static const std::array<EffectSpec, kDirectionCount> table = [] {
    CustomEffect slip;
    slip.name = "residual_features_lateral_slip";
    slip.parameters = {"a"};
    slip.key = "residual features";
    slip.lateral.text = "a";
    return std::array<EffectSpec, kDirectionCount>{EffectSpec{"scale_error", {1.0}}, EffectSpec{"wheelbase_error", {1.0}},
                                                   EffectSpec{"wheel_diameter_ratio", {1.0}},
                                                   define_custom_effect(std::move(slip), {0.0})};
  }();
  return table;
}

/// The model moved by kSensitivityStep along one direction: its effect's value moved, or the
/// effect added at its neutral value plus the step.
SuiteModel nudged(const SuiteModel& model, const EffectSpec& direction) {
  SuiteModel m = model;
  EffectSpec* e = find_spec(m.effects, direction.name);
  if (!e) e = &m.effects.emplace_back(direction);
  e->values[0] += kSensitivityStep;
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
  sum.acceleration_mps += f.acceleration_mps / n;
  sum.heading_cos += f.heading_cos / n;
  sum.heading_sin += f.heading_sin / n;
  sum.heading_known = sum.heading_known && f.heading_known;
}

/// Each run's path features.
std::vector<PathFeatures> run_path_features(const SuiteExperiment& ex, double wheelbase_m) {
  std::vector<PathFeatures> out;
  for (const SuiteRun& run : ex.runs) out.push_back(path_features(ex, run, wheelbase_m));
  return out;
}

/// An experiment's path features: the mean of its runs' (heading_known only when every run's
/// start heading is).
PathFeatures mean_path_features(const std::vector<PathFeatures>& runs) {
  PathFeatures sum;
  sum.heading_known = true;  // until a run without its start heading
  const double n = static_cast<double>(runs.size());
  for (const PathFeatures& f : runs) add_features(sum, f, n);
  return sum;
}

/// True when the runs of `ex` give their start headings and these are not all the same: the
/// experiments the run part of a feature (run_feature_test) can use.
bool headings_differ(const SuiteExperiment& ex) {
  if (ex.runs.size() < 2) return false;
  bool differ = false;
  for (const SuiteRun& run : ex.runs) {
    if (!run.heading0_given) return false;
    differ = differ || run.heading0_rad != ex.runs.front().heading0_rad;
  }
  return differ;
}

/// The scatter part of an experiment (see residual_alignment): W_e = sum d_i' Sigma_i^-1 d_i
/// with d_i the end-frame residuals about their own mean, over its expectation under the model
/// (scatter_ratio); shape 0 (no scatter part) for a lone run, a covariance that cannot be
/// inverted or no scatter at all.
void experiment_scatter(const std::vector<Vector3>& r, const std::vector<Matrix3>& cov, ExperimentMean& m) {
  const std::optional<double> ratio = scatter_ratio(r, cov);
  if (!ratio || !(*ratio > 0)) return;
  m.scatter = *ratio;
  m.shape = 0.5 * kDim * (static_cast<double>(r.size()) - 1.0);
}

/// Experiment e's mean residual, its sensitivities to the directions (from the nudged
/// models' residuals `nudges`) and its covariance, all in the runs' end frames, with its mean
/// features, group and scatter part. False when the covariance is not positive definite (no
/// test can use the experiment).
bool experiment_mean(const SuiteExperiment& ex, std::size_t e, const Residuals& residuals,
                     const std::vector<const Residuals*>& nudges, double B, ExperimentMean& m) {
  const double n = static_cast<double>(ex.runs.size());
  Matrix3 C = Matrix3::Zero();
  std::vector<Vector3> runs;
  std::vector<Matrix3> covs;
  for (std::size_t r = 0; r < ex.runs.size(); ++r) {
    const Matrix3 R = end_frame(odometry_end_pose(ex, ex.runs[r], B).z());
    const RunResidual& res = residuals[e][r];
    runs.push_back(R * (res.error - res.mean));
    covs.push_back(R * res.cov * R.transpose());
    m.frames.push_back(R);
    m.r += runs.back() / n;
    m.V += R.leftCols<kStartFrameTerms>() / n;
    for (int j = 0; j < kDirectionCount; ++j) {
      m.S.col(j) += R * ((*nudges[static_cast<std::size_t>(j)])[e][r].mean - res.mean) / (kSensitivityStep * n);
    }
    C += covs.back() / (n * n);
  }
  const Eigen::LDLT<Matrix3> ldlt(C);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return false;
  m.W = ldlt.solve(Matrix3::Identity());
  m.run_features = run_path_features(ex, B);
  m.features = mean_path_features(m.run_features);
  m.group = experiment_group(ex);
  m.experiment = e;
  m.headings_differ = headings_differ(ex);
  experiment_scatter(runs, covs, m);
  m.covs = std::move(covs);
  m.runs = std::move(runs);
  return true;
}

/// The means of every experiment with runs and a usable covariance; `nudges` are the residuals
/// of the model nudged along each of directions() (the first-order sensitivity of every run's
/// predicted mean to each direction).
std::vector<ExperimentMean> experiment_means(const Suite& suite, const SuiteModel& model, const Residuals& residuals,
                                             const std::vector<const Residuals*>& nudges) {
  const double B = model.robot.wheelbase_m;
  std::vector<ExperimentMean> ms;
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    if (ex.runs.empty()) continue;
    ExperimentMean m;
    if (experiment_mean(ex, e, residuals, nudges, B, m)) ms.push_back(std::move(m));
  }
  return ms;
}

/// A feature's columns over the experiments, each centred and scaled to at most 1 in absolute
/// value (the fits do not depend on it, their conditioning does); the columns that do not vary
/// across the experiments are dropped, and a feature of the heading has none unless every run's
/// start heading is known.
std::vector<Eigen::VectorXd> feature_columns(const std::vector<const ExperimentMean*>& ms, const Feature& f) {
  std::vector<Eigen::VectorXd> out;
  const auto heading_unknown = [](const ExperimentMean* m) { return !m->features.heading_known; };
  if (f.needs_heading && std::any_of(ms.begin(), ms.end(), heading_unknown)) return out;
  const auto m = static_cast<Eigen::Index>(ms.size());
  for (int c = 0; c < f.columns; ++c) {
    Eigen::VectorXd v(m);
    for (Eigen::Index e = 0; e < m; ++e) v(e) = f.value(ms[static_cast<std::size_t>(e)]->features, c);
    if (m == 0) continue;
    const double mean = v.mean();
    v.array() -= mean;
    const double spread = v.cwiseAbs().maxCoeff();
    if (!(spread > 1e-9 * std::max(1.0, std::abs(mean))) || !std::isfinite(spread)) continue;
    out.push_back(v / spread);
  }
  return out;
}

/// Mean part of a path feature: the base design X0 plus the terms M modulated by each of the
/// feature's columns; F test against X0, untestable when the feature does not vary.
void mean_feature_test(const std::vector<ExperimentMean>& ms, const MeanDesign& d, const Feature& f,
                       ResidualAlignment& a) {
  const std::vector<Eigen::MatrixXd>& X0 = d.base;
  const std::vector<Eigen::MatrixXd>& M = d.modulated;
  std::vector<const ExperimentMean*> all;
  for (const ExperimentMean& m : ms) all.push_back(&m);
  const std::vector<Eigen::VectorXd> cols = feature_columns(all, f);
  if (cols.empty()) return;
  std::vector<Eigen::MatrixXd> X1;
  for (std::size_t e = 0; e < ms.size(); ++e) {
    const Eigen::Index p0 = X0[e].cols(), q = M[e].cols();
    Eigen::MatrixXd x(kDim, p0 + q * static_cast<Eigen::Index>(cols.size()));
    x.leftCols(p0) = X0[e];
    for (std::size_t c = 0; c < cols.size(); ++c) {
      x.middleCols(p0 + q * static_cast<Eigen::Index>(c), q) = cols[c](static_cast<Eigen::Index>(e)) * M[e];
    }
    X1.push_back(x);
  }
  f_test(ms, d, X1, a);
}

/// A feature's columns over an experiment's runs about their mean, those that vary scaled to at
/// most 1 in absolute value.
std::vector<Eigen::VectorXd> run_columns(const ExperimentMean& m, const Feature& f) {
  const auto n = static_cast<Eigen::Index>(m.runs.size());
  std::vector<Eigen::VectorXd> cols;
  for (int c = 0; c < f.columns; ++c) {
    Eigen::VectorXd v(n);
    for (Eigen::Index i = 0; i < n; ++i) v(i) = f.value(m.run_features[static_cast<std::size_t>(i)], c);
    v.array() -= v.mean();
    const double widest = v.cwiseAbs().maxCoeff();
    if (widest > 1e-9 && std::isfinite(widest)) cols.push_back(v / widest);
  }
  return cols;
}

/// One experiment's share of the run part: its runs' weighted sum of squares about their mean
/// (RSS0), the part of it its own coefficients on the feature's columns explain, and their
/// number; not ok when a run's covariance cannot be inverted.
struct RunShare {
  double rss0 = 0.0, explained = 0.0;
  int parameters = 0;
  bool ok = true;
};

RunShare run_share(const ExperimentMean& m, const Feature& f) {
  const std::vector<Eigen::VectorXd> cols = run_columns(m, f);
  const auto n = static_cast<Eigen::Index>(m.runs.size());
  const auto p = static_cast<Eigen::Index>(kDim * cols.size());
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(p, p), X(kDim, p);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(p);
  Vector3 mean = Vector3::Zero();
  for (const Vector3& r : m.runs) mean += r / static_cast<double>(n);
  RunShare out;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Eigen::LDLT<Matrix3> ldlt(m.covs[static_cast<std::size_t>(i)]);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0)) return {0.0, 0.0, 0, false};
    const Matrix3 W = ldlt.solve(Matrix3::Identity());
    const Vector3 d = m.runs[static_cast<std::size_t>(i)] - mean;
    out.rss0 += d.dot(W * d);
    for (std::size_t c = 0; c < cols.size(); ++c) {
      X.middleCols(static_cast<Eigen::Index>(kDim * c), kDim) = cols[c](i) * Matrix3::Identity();
    }
    A += X.transpose() * W * X;
    b += X.transpose() * W * d;
  }
  const Eigen::LDLT<Eigen::MatrixXd> fit(A);
  if (p == 0 || fit.info() != Eigen::Success || !(fit.vectorD().minCoeff() > 0)) return out;  // its columns add nothing
  out.explained = b.dot(fit.solve(b));
  out.parameters = static_cast<int>(p);
  return out;
}

/// Run part of a feature in which the runs of one experiment differ by design (Feature::run):
/// over the experiments whose runs started at different headings, each run's end-frame residual
/// about its experiment's mean, d_i, against the feature's columns about theirs, g_i, in
/// weighted least squares (Sigma_i^-1), with each experiment's own coefficients:
///   H1: d_i = sum_c g_ic a_ec (a_ec in R^3)   against   H0: d_i = 0.
/// The runs of an experiment drive one path turned by their start headings psi0, so an error
/// that depends on the heading linearly in its cos and sin is linear in (cos psi0, sin psi0)
/// there, and so is the path's mean heading (the columns); how it scales from one path to
/// another (with the distance, the turns) is the experiment's own. F = ((RSS0 - RSS1)/q) /
/// (RSS1/(nu - q)) ~ F(q, nu - q), q = 3 x the columns that vary, summed over the experiments,
/// nu = 3 sum_e (n_e - 1): the within-experiment analysis of variance, its scale estimated from
/// RSS1, so a spread predicted too small or too large does not count, only one that follows the
/// feature. Untestable when no experiment qualifies or nothing varies.
void run_feature_test(const std::vector<ExperimentMean>& ms, const Feature& f, ResidualAlignment& a) {
  double rss0 = 0.0, explained = 0.0;
  int q = 0, nu = 0;
  for (const ExperimentMean& m : ms) {
    if (!m.headings_differ) continue;
    const RunShare share = run_share(m, f);
    if (!share.ok) return;
    rss0 += share.rss0;
    explained += share.explained;
    q += share.parameters;
    nu += kDim * static_cast<int>(m.runs.size() - 1);
  }
  const double rss1 = rss0 - explained;
  if (q == 0 || nu - q <= 0 || !(rss1 > 0) || !std::isfinite(rss0)) return;
  f_result(std::max(0.0, explained / q) / (rss1 / (nu - q)), q, nu - q, a);
}

/// The groups of the experiments, indexed in order of first appearance.
std::vector<int> group_indices(const std::vector<const ExperimentMean*>& ms, int& groups) {
  std::map<std::string, int> index;
  std::vector<int> out;
  for (const ExperimentMean* m : ms) out.push_back(index.emplace(m->group, static_cast<int>(index.size())).first->second);
  groups = static_cast<int>(index.size());
  return out;
}

/// Mean part of the groups: one-way ANOVA, the base terms per group against common ones;
/// untestable with fewer than two groups.
void mean_group_test(const std::vector<ExperimentMean>& ms, const MeanDesign& d, ResidualAlignment& a) {
  std::vector<const ExperimentMean*> all;
  for (const ExperimentMean& m : ms) all.push_back(&m);
  int groups = 0;
  const std::vector<int> g = group_indices(all, groups);
  if (groups < 2) return;
  std::vector<Eigen::MatrixXd> X1;
  for (std::size_t e = 0; e < ms.size(); ++e) {
    Eigen::MatrixXd x = Eigen::MatrixXd::Zero(kDim, kBaseTerms * groups);
    x.middleCols(kBaseTerms * g[e], kBaseTerms) = d.base[e];
    X1.push_back(x);
  }
  f_test(ms, d, X1, a);
}

/// A gamma GLM with log link and known shapes k_e [McCullagh89, ch. 8], fitted by iteratively
/// reweighted least squares (with the log link the working weights are the shapes):
/// its deviance 2 sum k ((s - mu)/mu - ln(s/mu)) and Pearson statistic sum k (s - mu)^2/mu^2.
struct GammaFit {
  double deviance = 0.0, pearson = 0.0;
  bool ok = false;
};

/// IRLS iterations at most, and the change in the coefficients that ends them.
constexpr int kGlmIterations = 50;
constexpr double kGlmTolerance = 1e-10;

GammaFit gamma_fit(const Eigen::VectorXd& s, const Eigen::VectorXd& k, const Eigen::MatrixXd& X) {
  Eigen::VectorXd beta = Eigen::VectorXd::Zero(X.cols());
  beta(0) = std::log(k.dot(s) / k.sum());  // the first column is the intercept
  for (int it = 0; it < kGlmIterations; ++it) {
    const Eigen::VectorXd eta = X * beta;
    const Eigen::VectorXd mu = eta.array().exp();
    const Eigen::VectorXd z = eta.array() + (s.array() - mu.array()) / mu.array();
    const Eigen::MatrixXd A = X.transpose() * k.asDiagonal() * X;
    const Eigen::VectorXd next = A.ldlt().solve(X.transpose() * k.asDiagonal() * z);
    if (!next.allFinite()) return {};
    const double change = (next - beta).cwiseAbs().maxCoeff();
    beta = next;
    if (change < kGlmTolerance) break;
  }
  const Eigen::ArrayXd mu = (X * beta).array().exp();
  GammaFit f;
  f.deviance = 2.0 * (k.array() * ((s.array() - mu) / mu - (s.array() / mu).log())).sum();
  f.pearson = (k.array() * (s.array() - mu).square() / mu.square()).sum();
  f.ok = std::isfinite(f.deviance) && f.pearson > 0;
  return f;
}

/// Scatter part: the gamma GLM of the experiments' scatter ratios on the design X1 (an
/// intercept first) against the intercept alone, with the dispersion estimated from H1's
/// Pearson statistic: F = ((D0 - D1)/q) / (X1^2/(m - p1)) ~ F(q, m - p1); or, when every
/// experiment's dispersion is known from the model's simulated world, with the weights k_e/phi_e:
/// D0 - D1 ~ chi^2(q).
void scatter_test(const std::vector<const ExperimentMean*>& ms, const Eigen::MatrixXd& X1, ResidualAlignment& a) {
  const auto m = static_cast<Eigen::Index>(ms.size());
  const auto p1 = X1.cols();
  if (p1 < 2 || m - p1 <= 0) return;
  // Known only when every experiment's is: otherwise the F test, on the shapes alone.
  const bool known = std::all_of(ms.begin(), ms.end(), [](const ExperimentMean* x) { return x->dispersion > 0; });
  Eigen::VectorXd s(m), k(m);
  for (Eigen::Index e = 0; e < m; ++e) {
    const ExperimentMean& x = *ms[static_cast<std::size_t>(e)];
    s(e) = x.scatter;
    k(e) = known ? x.shape / x.dispersion : x.shape;
  }
  const GammaFit h0 = gamma_fit(s, k, Eigen::MatrixXd::Ones(m, 1));
  const GammaFit h1 = gamma_fit(s, k, X1);
  if (!h0.ok || !h1.ok) return;
  const auto q = static_cast<int>(p1 - 1), dof2 = static_cast<int>(m - p1);
  if (!known) {
    const double dispersion = h1.pearson / dof2;
    f_result(std::max(0.0, (h0.deviance - h1.deviance) / q) / dispersion, q, dof2, a);
    return;
  }
  a.dof1 = q;
  a.dof2 = 0;
  a.statistic = std::max(0.0, h0.deviance - h1.deviance);
  a.p_value_raw = a.statistic > 0 ? boost::math::cdf(boost::math::complement(boost::math::chi_squared(q), a.statistic)) : 1.0;
  a.testable = true;
}

/// Each experiment's dispersion phi_e = k_e Var(s_e) over `replicates` suites simulated from the
/// model: the runs' errors drawn anew, their scatter ratio computed as the data's (the same
/// predicted means, covariances and end frames). Left at 0 (unknown) when the model's effects
/// cannot be simulated on some run, or a replicate's ratio is not finite.
void simulated_dispersions(const Suite& suite, const SuiteModel& model, const Residuals& residuals,
                           const SimulatedDispersion& sim, std::vector<ExperimentMean>& ms) {
  std::vector<Vector3> errors;
  std::size_t runs = 0;
  try {
    const ModelWorld world(suite, model, sim.seed);
    world.errors(0, sim.replicates, errors);
    runs = world.runs();
  } catch (const EffectError&) {
    return;
  }
  std::vector<std::size_t> first(suite.experiments.size() + 1, 0);
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) first[e + 1] = first[e] + suite.experiments[e].runs.size();
  std::vector<Vector3> r;
  for (ExperimentMean& m : ms) {
    if (!(m.shape > 0)) continue;
    const std::size_t e = m.experiment, n = suite.experiments[e].runs.size();
    double mean = 0.0, m2 = 0.0;  // Welford over the replicates
    bool ok = true;
    for (int b = 0; b < sim.replicates && ok; ++b) {
      r.clear();
      for (std::size_t i = 0; i < n; ++i) {
        r.push_back(m.frames[i] * (errors[static_cast<std::size_t>(b) * runs + first[e] + i] - residuals[e][i].mean));
      }
      ExperimentMean x;
      experiment_scatter(r, m.covs, x);
      ok = x.shape > 0 && std::isfinite(x.scatter);
      const double delta = x.scatter - mean;
      mean += delta / (b + 1);
      m2 += delta * (x.scatter - mean);
    }
    if (ok && sim.replicates > 1) m.dispersion = m.shape * m2 / (sim.replicates - 1);
  }
}

/// The scatter part of one feature: log E s_e linear in the feature's columns (a variance that
/// grows with it), or for the groups one level per group.
void scatter_feature_test(const std::vector<ExperimentMean>& all, const Feature& f, ResidualAlignment& a) {
  std::vector<const ExperimentMean*> ms;
  for (const ExperimentMean& m : all) {
    if (m.shape > 0) ms.push_back(&m);
  }
  const auto m = static_cast<Eigen::Index>(ms.size());
  Eigen::MatrixXd X;
  if (f.columns == 0) {
    int groups = 0;
    const std::vector<int> g = group_indices(ms, groups);
    if (groups < 2) return;
    X = Eigen::MatrixXd::Zero(m, groups);
    X.col(0).setOnes();
    for (Eigen::Index e = 0; e < m; ++e) {
      if (g[static_cast<std::size_t>(e)] > 0) X(e, g[static_cast<std::size_t>(e)]) = 1.0;
    }
  } else {
    const std::vector<Eigen::VectorXd> cols = feature_columns(ms, f);
    X = Eigen::MatrixXd::Ones(m, static_cast<Eigen::Index>(1 + cols.size()));
    for (std::size_t c = 0; c < cols.size(); ++c) X.col(static_cast<Eigen::Index>(c + 1)) = cols[c];
  }
  scatter_test(ms, X, a);
}

/// Family-wise p-values (Bonferroni over every testable feature and part), then testable ones
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
  FeatureAccumulator acc(wheelbase_m, run.heading0_rad);
  if (ex.logged) {
    for (std::size_t i = 0; i < run.pieces.size(); ++i) {
      acc.add(run.pieces[i], i < run.durations_s.size() ? run.durations_s[i] : 0.0);
    }
  } else {
    for (std::size_t i = 0; i < ex.path.interval_count(); ++i) {
      acc.add(ex.path.interval(i), ex.path.keyframes[i + 1].t_s - ex.path.keyframes[i].t_s);
    }
  }
  PathFeatures f = acc.result();
  f.heading_known = run.heading0_given;
  return f;
}

std::string experiment_group(const SuiteExperiment& ex) { return group_key(ex); }

bool runs_start_at_different_headings(const Suite& suite) {
  return std::any_of(suite.experiments.begin(), suite.experiments.end(), headings_differ);
}

std::vector<double> experiment_feature_values(const Suite& suite, double wheelbase_m, const std::string& feature) {
  const auto f = std::find_if(features().begin(), features().end(),
                              [&](const Feature& x) { return feature == x.name && x.columns > 0; });
  std::vector<double> out(suite.experiments.size(), std::numeric_limits<double>::quiet_NaN());
  if (f == features().end()) return out;
  std::vector<PathFeatures> means;
  for (const SuiteExperiment& ex : suite.experiments) {
    means.push_back(mean_path_features(run_path_features(ex, wheelbase_m)));
    if (f->needs_heading && !ex.runs.empty() && !means.back().heading_known) return out;
  }
  // The column that varies more (the heading's cos or sin).
  int column = 0;
  double widest = -1.0;
  for (int c = 0; c < f->columns; ++c) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (std::size_t e = 0; e < means.size(); ++e) {
      if (suite.experiments[e].runs.empty()) continue;
      lo = std::min(lo, f->value(means[e], c));
      hi = std::max(hi, f->value(means[e], c));
    }
    if (hi - lo > widest) widest = hi - lo, column = c;
  }
  for (std::size_t e = 0; e < means.size(); ++e) {
    if (!suite.experiments[e].runs.empty()) out[e] = f->value(means[e], column);
  }
  return out;
}

const std::vector<std::string>& residual_feature_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> out;
    for (const Feature& f : features()) out.emplace_back(f.name);
    return out;
  }();
  return names;
}

namespace {

/// residual_alignment with the nudged models' residuals given.
std::vector<ResidualAlignment> alignment(const Suite& suite, const SuiteModel& model, const Residuals& residuals,
                                         const std::vector<const Residuals*>& nudges,
                                         const SimulatedDispersion* simulated) {
  std::vector<ExperimentMean> ms = experiment_means(suite, model, residuals, nudges);
  if (simulated) simulated_dispersions(suite, model, residuals, *simulated, ms);
  // Mean part, H0: the misfit is a constant offset in the end frame and one in the start frame
  // (a marker off the axle centre makes both: R(theta) d - d), plus constant factor errors and a
  // constant sideways slip, r_e = [I3 V_e S_e] c. H1 adds the physical terms modulated by the
  // feature, f_e [e_theta V_e S_e] d: a scale, wheelbase, diameter ratio or sideways slip, a
  // heading offset, or an offset in the start frame, that varies with the feature (one that grows
  // with the distance: a floor that pushes every run the same way, where runs start aligned).
  const MeanDesign design = mean_design(ms);
  const bool run_part = std::any_of(ms.begin(), ms.end(), [](const ExperimentMean& m) { return m.headings_differ; });
  std::vector<ResidualAlignment> out;
  for (const Feature& f : features()) {
    if (f.run && run_part) {
      ResidualAlignment run;
      run.feature = f.name;
      run.part = "run";
      run.description = f.run;
      run_feature_test(ms, f, run);
      out.push_back(std::move(run));
    }
    ResidualAlignment mean, scatter;
    mean.feature = scatter.feature = f.name;
    mean.part = "mean";
    scatter.part = "scatter";
    mean.description = f.mean;
    scatter.description = f.scatter;
    if (!ms.empty()) {
      if (f.columns == 0) {
        mean_group_test(ms, design, mean);
      } else {
        mean_feature_test(ms, design, f, mean);
      }
      scatter_feature_test(ms, f, scatter);
    }
    out.push_back(std::move(mean));
    out.push_back(std::move(scatter));
  }
  adjust_and_rank(out);
  return out;
}

}  // namespace

std::vector<ResidualAlignment> residual_alignment(const Suite& suite, const SuiteModel& model,
                                                  const Residuals& residuals, const SimulatedDispersion* simulated) {
  std::vector<Residuals> nudges;
  for (const EffectSpec& d : directions()) nudges.push_back(odomcov::residuals(suite, nudged(model, d)));
  std::vector<const Residuals*> read;
  for (const Residuals& r : nudges) read.push_back(&r);
  return alignment(suite, model, residuals, read, simulated);
}

std::vector<ResidualAlignment> residual_alignment(ResidualCache& cache, const SuiteModel& model,
                                                  const SimulatedDispersion* simulated) {
  std::vector<const Residuals*> nudges;  // the cache's entries stay where they are until it ages
  for (const EffectSpec& d : directions()) nudges.push_back(&cache.full(nudged(model, d)));
  return alignment(cache.suite(), model, cache.full(model), nudges, simulated);
}

}  // namespace odomcov
