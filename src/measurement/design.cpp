#include "odomcov/measurement/design.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <optional>
#include <set>

#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/measurement/residual_features.hpp"

namespace odomcov {
namespace {

using Residuals = std::vector<std::vector<RunResidual>>;

/// The central-difference step of a fitted value: a ten-thousandth of its size (at least of
/// 1e-3, so that a parameter at 0 still moves), and whether v - h is still a valid value (else
/// a forward difference).
struct Step {
  double h = 0.0;
  bool central = true;
};

bool valid_value(SuiteModel model, const std::string& name, double v) {
  fitted_parameter(model, name) = v;
  if (model.robot.noise.k_left < 0 || model.robot.noise.k_right < 0 || !(model.robot.wheelbase_m > 0)) return false;
  for (const EffectSpec& e : model.effects) {
    if (!check_effect(e).empty()) return false;
  }
  return true;
}

Step step_of(const SuiteModel& model, const std::string& name) {
  SuiteModel m = model;
  const double v = fitted_parameter(m, name);
  const double h = 1e-4 * std::max(std::abs(v), 1e-3);
  return {h, valid_value(model, name, v - h)};
}

/// The residuals of `suite` at the model and, per fitted parameter, at v + h and v - h (or
/// v + 2h for a forward difference): their derivatives come from these.
struct Sensitivities {
  Residuals at;
  std::vector<Residuals> plus, minus;
  std::vector<Step> steps;
};

Sensitivities sensitivities(const Suite& suite, const SuiteModel& model, const std::vector<std::string>& names) {
  Sensitivities s;
  s.at = residuals(suite, model);
  for (const std::string& name : names) {
    Step step = step_of(model, name);
    SuiteModel m = model;
    const double v = fitted_parameter(m, name);
    // The residuals at v + o, or nothing where the model cannot be computed there (a custom
    // expression's wall beside a parameter that sits at it, e.g. a noise factor a at 0).
    auto moved = [&](double o) -> std::optional<Residuals> {
      fitted_parameter(m, name) = v + o;
      try {
        return residuals(suite, m);
      } catch (const InputError&) {
        return std::nullopt;
      }
    };
    std::optional<Residuals> plus = moved(step.h);
    std::optional<Residuals> minus = step.central ? moved(-step.h) : std::nullopt;
    if (plus && minus) {  // central
      s.plus.push_back(std::move(*plus));
      s.minus.push_back(std::move(*minus));
    } else if (plus) {  // forward: v - h is out of range or walled
      step.central = false;
      s.plus.push_back(std::move(*plus));
      s.minus.push_back(s.at);
    } else if (minus) {  // backward: v + h is walled
      step.central = false;
      s.plus.push_back(s.at);
      s.minus.push_back(std::move(*minus));
    } else {  // walled on both sides: the error of v + h
      fitted_parameter(m, name) = v + step.h;
      s.plus.push_back(residuals(suite, m));
    }
    s.steps.push_back(step);
  }
  return s;
}

/// A run's residual r = error - mean, covariance S and group columns U, stacked for a set of
/// runs: dense vectors and matrices in 3-row blocks.
struct Stacked {
  Eigen::VectorXd r;
  Eigen::MatrixXd S, U;
};

Stacked stack(const std::vector<const RunResidual*>& runs) {
  const auto n = static_cast<Eigen::Index>(runs.size());
  Stacked out{Eigen::VectorXd(3 * n), Eigen::MatrixXd::Zero(3 * n, 3 * n), Eigen::MatrixXd(3 * n, 2)};
  for (Eigen::Index i = 0; i < n; ++i) {
    const RunResidual& run = *runs[static_cast<std::size_t>(i)];
    out.r.segment<3>(3 * i) = run.error - run.mean;
    out.S.block<3, 3>(3 * i, 3 * i) = run.cov;
    out.U.block<3, 1>(3 * i, 0) = run.group_column;
    out.U.block<3, 1>(3 * i, 1) = run.group_column2;
  }
  return out;
}

/// The Gaussian Fisher information of a stacked set of runs with covariance C = S + U U^T (the
/// U term only when `grouped`), from the sets at v + h and v - h per parameter:
///   I_kl = dr_k' C^-1 dr_l + tr(C^-1 dC_k C^-1 dC_l) / 2;
/// and, when `score` is given, adds the log-likelihood's gradient to it:
///   g_k = -dr_k' C^-1 r + (r' C^-1 dC_k C^-1 r - tr(C^-1 dC_k)) / 2.
Eigen::MatrixXd information_of(const Stacked& at, const std::vector<Stacked>& plus,
                               const std::vector<Stacked>& minus, const std::vector<double>& width,
                               bool grouped, Eigen::VectorXd* score = nullptr) {
  const std::size_t n = plus.size();
  auto cov = [grouped](const Stacked& s) -> Eigen::MatrixXd {
    return grouped ? Eigen::MatrixXd(s.S + s.U * s.U.transpose()) : s.S;
  };
  const Eigen::LDLT<Eigen::MatrixXd> C(cov(at));
  std::vector<Eigen::VectorXd> dr(n);
  std::vector<Eigen::MatrixXd> CdC(n);
  for (std::size_t k = 0; k < n; ++k) {
    dr[k] = (plus[k].r - minus[k].r) / width[k];
    CdC[k] = C.solve((cov(plus[k]) - cov(minus[k])) / width[k]);
  }
  if (score) {
    const Eigen::VectorXd Cr = C.solve(at.r);
    for (std::size_t k = 0; k < n; ++k) {
      const Eigen::VectorXd CdCCr = CdC[k] * Cr;
      (*score)(static_cast<Eigen::Index>(k)) += -dr[k].dot(Cr) + 0.5 * (at.r.dot(CdCCr) - CdC[k].trace());
    }
  }
  Eigen::MatrixXd I(n, n);
  for (std::size_t k = 0; k < n; ++k) {
    const Eigen::VectorXd Cdr = C.solve(dr[k]);
    for (std::size_t l = 0; l <= k; ++l) {
      const double trace = (CdC[k].array() * CdC[l].transpose().array()).sum();
      I(k, l) = I(l, k) = dr[l].dot(Cdr) + 0.5 * trace;
    }
  }
  return I;
}

/// The runs of each group (RunResidual::group) of a set of residuals, in order.
std::map<int, std::vector<std::pair<std::size_t, std::size_t>>> runs_by_group(const Residuals& res) {
  std::map<int, std::vector<std::pair<std::size_t, std::size_t>>> out;
  for (std::size_t e = 0; e < res.size(); ++e) {
    for (std::size_t r = 0; r < res[e].size(); ++r) out[res[e][r].group].push_back({e, r});
  }
  return out;
}

bool has_group_columns(const Residuals& res) {
  for (const auto& ex : res) {
    for (const RunResidual& r : ex) {
      if (!r.group_column.isZero(0.0) || !r.group_column2.isZero(0.0)) return true;
    }
  }
  return false;
}

/// The information of one set of runs (a group, or a single run) from the sensitivities.
Eigen::MatrixXd information_of_runs(const Sensitivities& s, const std::vector<std::pair<std::size_t, std::size_t>>& runs,
                                    bool grouped, Eigen::VectorXd* score = nullptr) {
  auto pick = [&](const Residuals& res) {
    std::vector<const RunResidual*> out;
    for (const auto& [e, r] : runs) out.push_back(&res[e][r]);
    return stack(out);
  };
  std::vector<Stacked> plus, minus;
  std::vector<double> width;
  for (std::size_t k = 0; k < s.plus.size(); ++k) {
    plus.push_back(pick(s.plus[k]));
    minus.push_back(pick(s.minus[k]));
    width.push_back(s.steps[k].central ? 2 * s.steps[k].h : s.steps[k].h);
  }
  return information_of(pick(s.at), plus, minus, width, grouped, score);
}

/// The information of the runs of a suite from their sensitivities: each group's runs jointly
/// when the model correlates them, each run alone otherwise; and their log-likelihood's gradient
/// into `score` when given.
Eigen::MatrixXd information(const Sensitivities& s, Eigen::VectorXd* score = nullptr) {
  const auto n = static_cast<Eigen::Index>(s.plus.size());
  Eigen::MatrixXd I = Eigen::MatrixXd::Zero(n, n);
  if (score) *score = Eigen::VectorXd::Zero(n);
  const bool grouped = has_group_columns(s.at);
  for (const auto& [group, runs] : runs_by_group(s.at)) {
    if (grouped) {
      I += information_of_runs(s, runs, true, score);
      continue;
    }
    for (const auto& run : runs) I += information_of_runs(s, {run}, false, score);
  }
  return I;
}

/// The information of n runs of one planned experiment as a new group: its runs' mean has
/// covariance S/n + U U^T, and their scatter about it is Wishart(S, n - 1), independent of it:
///   I = I_mean(S/n + U U^T) + (n - 1) I_scatter(S).
Eigen::MatrixXd information_of_experiment(const Sensitivities& s, std::size_t experiment, std::int64_t runs) {
  const double n = static_cast<double>(runs);
  auto pick = [&](const Residuals& res, bool mean) {
    Stacked out = stack({&res[experiment][0]});
    if (mean) {
      out.S /= n;
    } else {
      out.U.setZero();
    }
    return out;
  };
  Eigen::MatrixXd total;
  for (const bool mean : {true, false}) {
    std::vector<Stacked> plus, minus;
    std::vector<double> width;
    for (std::size_t k = 0; k < s.plus.size(); ++k) {
      plus.push_back(pick(s.plus[k], mean));
      minus.push_back(pick(s.minus[k], mean));
      width.push_back(s.steps[k].central ? 2 * s.steps[k].h : s.steps[k].h);
    }
    Stacked at = pick(s.at, mean);
    if (!mean) {  // the scatter carries no mean information
      at.r.setZero();
      for (auto* list : {&plus, &minus}) {
        for (Stacked& x : *list) x.r.setZero();
      }
    }
    const Eigen::MatrixXd I = information_of(at, plus, minus, width, mean);
    total = mean ? I : Eigen::MatrixXd(total + (n - 1) * I);
  }
  return total;
}

// ---- The menu ---------------------------------------------------------------------------------

/// The suite's sample rate: its first planned path's, else the median of its logs' 1/duration.
double sample_rate_of(const Suite& suite) {
  std::vector<double> rates;
  for (const SuiteExperiment& ex : suite.experiments) {
    if (!ex.logged) return ex.path.sample_rate_hz;
    for (const SuiteRun& run : ex.runs) {
      for (double d : run.durations_s) rates.push_back(1.0 / d);
    }
  }
  if (rates.empty()) return 50.0;
  std::nth_element(rates.begin(), rates.begin() + static_cast<std::ptrdiff_t>(rates.size() / 2), rates.end());
  return rates[rates.size() / 2];
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

/// A planned path's `speed`: its faster wheel's speed, the largest over its intervals.
double planned_speed(const Path& path) {
  double v = 0.0;
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const ArcSegment a = path.interval(i);
    const double dt = path.keyframes[i + 1].t_s - path.keyframes[i].t_s;
    v = std::max(v, std::max(std::abs(a.left_m), std::abs(a.right_m)) / dt);
  }
  return v;
}

/// The suite's speeds (the menu's `speed`, its faster wheel's): its planned experiments'
/// distinct speeds (3 significant digits) when every experiment is planned and there are at
/// most three, else the median run speed (mean wheel speed); then half the slowest and twice
/// the fastest (in this order, so that among menu experiments that add the same information
/// the suite's own speed comes first).
std::vector<double> speeds_of(const Suite& suite) {
  std::set<double> planned;
  std::vector<double> runs;
  bool logged = false;
  for (const SuiteExperiment& ex : suite.experiments) {
    logged = logged || ex.logged;
    if (!ex.logged) planned.insert(std::stod(format_number(planned_speed(ex.path), "%.3g")));
    for (const SuiteRun& run : ex.runs) runs.push_back(path_features(ex, run, suite.robot.wheelbase_m).speed_mps);
  }
  std::vector<double> speeds(planned.begin(), planned.end());
  if (logged || speeds.empty() || speeds.size() > 3) speeds = {std::stod(format_number(median(runs), "%.3g"))};
  // Runs that do not move (a robot standing still) give no speed to plan at: no menu.
  speeds.erase(std::remove_if(speeds.begin(), speeds.end(), [](double v) { return !(v > 0.0 && std::isfinite(v)); }),
               speeds.end());
  if (speeds.empty()) return speeds;
  const double slow = 0.5 * speeds.front(), fast = 2.0 * speeds.back();
  speeds.push_back(slow);  // the suite's own speeds first: they win ties
  speeds.push_back(fast);
  return speeds;
}

std::int64_t runs_of(const Suite& suite) {
  std::vector<double> counts;
  for (const SuiteExperiment& ex : suite.experiments) counts.push_back(static_cast<double>(ex.runs.size()));
  return std::max<std::int64_t>(5, static_cast<std::int64_t>(median(counts)));
}

/// One menu entry: a name, its segments (as the suite's path block writes them) and the
/// segments themselves.
struct Recipe {
  std::string name;
  std::string segments_yaml;
  std::vector<PathSegment> segments;
};

PathSegment line(double d) { return {PathSegment::Kind::line, d, 0.0, 0.0}; }
PathSegment turn(double deg) { return {PathSegment::Kind::turn, 0.0, deg * M_PI / 180.0, 0.0}; }
PathSegment arc(double r, double deg) { return {PathSegment::Kind::arc, 0.0, deg * M_PI / 180.0, r}; }

std::vector<Recipe> recipes() {
  std::vector<Recipe> out;
  for (double d : {2.0, 5.0, 10.0}) {
    out.push_back({"line-" + format_number(d) + "m", "{line: " + format_number(d) + "}", {line(d)}});
  }
  out.push_back({"forward-back-3m", "{line: 3}, {line: -3}", {line(3), line(-3)}});
  for (double deg : {360.0, -360.0, 1080.0}) {
    out.push_back({std::string(deg > 0 ? "spin-ccw-" : "spin-cw-") + format_number(std::abs(deg)),
                   "{turn_deg: " + format_number(deg) + "}", {turn(deg)}});
  }
  for (double r : {0.5, 1.0, 2.0}) {
    for (double side : {1.0, -1.0}) {
      out.push_back({std::string(side > 0 ? "arc-left-r" : "arc-right-r") + format_number(r),
                     "{arc: {radius: " + format_number(side * r) + ", angle_deg: " + format_number(side * 180) + "}}",
                     {arc(side * r, side * 180)}});
    }
  }
  for (double side : {-90.0, 90.0}) {
    Recipe square{side < 0 ? "umbmark-cw-1m" : "umbmark-ccw-1m", "", {}};
    for (int i = 0; i < 4; ++i) {
      square.segments_yaml += std::string(i ? ", " : "") + "{line: 1}, {turn_deg: " + format_number(side) + "}";
      square.segments.push_back(line(1));
      square.segments.push_back(turn(side));
    }
    out.push_back(square);
  }
  return out;
}

/// Half the log-determinant of an information matrix (plus its ridge): from its LDLT pivots;
/// where rounding has left a pivot at or below 0 (parameters the runs do not determine, whose
/// information cancels to within rounding), from its eigenvalues, each at least the ridge's
/// smallest diagonal, so that a gain is a number and not NaN.
double half_log_det(const Eigen::MatrixXd& m, const Eigen::MatrixXd& ridge) {
  const Eigen::VectorXd d = Eigen::LDLT<Eigen::MatrixXd>(m).vectorD();
  if (d.size() == 0 || d.minCoeff() > 0.0) return 0.5 * d.array().log().sum();
  const Eigen::VectorXd lambda = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m, Eigen::EigenvaluesOnly).eigenvalues();
  return 0.5 * lambda.cwiseMax(ridge.diagonal().minCoeff()).array().log().sum();
}

}  // namespace

std::vector<ConfoundedPair> confounded_pairs(const std::vector<std::string>& names,
                                             const Eigen::MatrixXd& c) {
  std::vector<ConfoundedPair> out;
  for (Eigen::Index i = 0; i < c.rows(); ++i) {
    for (Eigen::Index j = i + 1; j < c.cols(); ++j) {
      const double r = c(i, j) / std::sqrt(c(i, i) * c(j, j));
      if (std::abs(r) > kConfoundedCorrelation) {
        out.push_back({names[static_cast<std::size_t>(i)], names[static_cast<std::size_t>(j)], r});
      }
    }
  }
  std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return std::abs(a.correlation) > std::abs(b.correlation); });
  return out;
}

std::string confounded_text(const ConfoundedPair& p) {
  return "these experiments do not separate " + p.a + " from " + p.b + " (correlation " +
         format_number(p.correlation, "%.3f") + "): the data fix a combination of the two, and " +
         (p.correlation > 0 ? "raising one while raising the other" : "raising one while lowering the other") +
         " fits almost as well; an experiment that moves only one of them separates them (next_experiments)";
}

Eigen::MatrixXd estimate_covariance(const Suite& suite, const FitResult& fit) {
  if (fit.covariance.size() > 0 && fit.covariance.allFinite()) return fit.covariance;
  const Eigen::MatrixXd I = fisher_information(suite, fit.model, fit.names);
  const Eigen::MatrixXd ridge = (1e-9 * I.diagonal().cwiseMax(1e-300)).asDiagonal();
  return (I + ridge).ldlt().solve(Eigen::MatrixXd::Identity(I.rows(), I.cols()));
}

std::vector<MenuExperiment> experiment_menu(const Suite& suite) {
  const double rate = sample_rate_of(suite);
  const std::int64_t runs = runs_of(suite);
  std::vector<MenuExperiment> out;
  for (double speed : speeds_of(suite)) {
    for (const Recipe& r : recipes()) {
      MenuExperiment m;
      m.name = r.name + "-" + format_number(speed, "%.3g") + "mps";
      m.path.sample_rate_hz = rate;
      m.path.keyframes = keyframes_from_segments(r.segments, suite.robot.wheelbase_m, speed);
      // A path the input limits would refuse (so slow that it needs more samples than a run may
      // have) is no experiment to record.
      if (!limits::check_path(m.path, suite.robot.wheelbase_m).empty()) continue;
      m.path_yaml = "{sample_rate: " + format_number(rate, "%.6g") + ", speed: " + format_number(speed, "%.6g") +
                    ", segments: [" + r.segments_yaml + "]}";
      m.runs = runs;
      out.push_back(std::move(m));
    }
  }
  return out;
}

Eigen::MatrixXd fisher_information(const Suite& suite, const SuiteModel& model,
                                   const std::vector<std::string>& names) {
  return information(sensitivities(suite, model, names));
}

namespace {

/// True when an effect of `list` contains `name` (EffectInfo::contains): its parameters already
/// span what `name` would add (turn_dependent_wheelbase with Eb_arc = Eb_spin = Eb).
bool contained(const EffectList& list, const std::string& name) {
  return std::any_of(list.begin(), list.end(), [&](const EffectSpec& e) {
    const EffectInfo* info = find_effect(e.name, list);
    return info && std::find(info->contains.begin(), info->contains.end(), name) != info->contains.end();
  });
}

}  // namespace

TrainingUncertainty training_uncertainty(const Suite& training, const SuiteModel& model,
                                         const std::vector<std::string>& fitted) {
  TrainingUncertainty u{model, fitted, std::vector<double>(fitted.size(), 0.0), {}, {}, {}, {}, {}};
  for (const EffectInfo& info : effect_catalogue()) {
    if (!info.systematic || info.grouped || find_spec(u.model.effects, info.name) ||
        u.model.effects.size() >= kMaxEffects || contained(u.model.effects, info.name)) {
      continue;
    }
    EffectSpec absent{info.name, {}};
    for (const EffectParameterInfo& p : info.parameters) absent.values.push_back(p.neutral);
    EffectList with = u.model.effects;
    with.push_back(absent);
    try {
      check_effects(with);
    } catch (const EffectError&) {
      continue;  // an effect the model's list does not admit beside its own
    }
    u.model.effects = std::move(with);
    for (const EffectParameterInfo& p : info.parameters) {
      u.names.push_back(info.name + "." + p.name);
      u.prior_sd.push_back(std::abs(p.typical - p.neutral));
    }
  }
  Eigen::VectorXd score;
  Eigen::MatrixXd I = information(sensitivities(training, u.model, u.names), &score);
  for (std::size_t k = 0; k < u.names.size(); ++k) {
    const auto i = static_cast<Eigen::Index>(k);
    if (u.prior_sd[k] > 0) I(i, i) += 1.0 / (u.prior_sd[k] * u.prior_sd[k]);
  }
  // A relative ridge of 1e-9, as for the estimates' covariance: a fitted parameter the training
  // runs do not determine at all stays finite.
  const Eigen::MatrixXd ridge = (1e-9 * I.diagonal().cwiseMax(1e-300)).asDiagonal();
  u.covariance = (I + ridge).ldlt().solve(Eigen::MatrixXd::Identity(I.rows(), I.cols()));
  // Given the unsized parameters at neutral: the inverse of the information's block of the sized
  // ones (the conditional covariance of a Gaussian), zero elsewhere.
  std::vector<Eigen::Index> kept;
  for (std::size_t k = 0; k < u.names.size(); ++k) {
    const auto i = static_cast<Eigen::Index>(k);
    u.sized.push_back(u.prior_sd[k] == 0 || std::sqrt(u.covariance(i, i)) <= kSizedPosteriorRatio * u.prior_sd[k]);
    if (u.sized.back()) kept.push_back(i);
  }
  const Eigen::MatrixXd block = (I + ridge)(kept, kept);
  const Eigen::MatrixXd inverse = block.ldlt().solve(Eigen::MatrixXd::Identity(block.rows(), block.cols()));
  u.covariance_sized = Eigen::MatrixXd::Zero(I.rows(), I.cols());
  u.covariance_sized(kept, kept) = inverse;
  // The posterior means: one Newton step of the log-posterior from the model (the priors' means
  // are where it starts, so their gradient is 0 there).
  u.shift = u.covariance * score;
  u.shift_sized = Eigen::VectorXd::Zero(score.size());
  u.shift_sized(kept) = inverse * score(kept);
  return u;
}

namespace {

using MeanJacobian = Eigen::Matrix<double, 3, Eigen::Dynamic>;

/// The derivative of the predicted mean of run r of experiment e in the parameters.
MeanJacobian mean_jacobian(const Sensitivities& s, std::size_t e, std::size_t r) {
  MeanJacobian J(3, static_cast<Eigen::Index>(s.steps.size()));
  for (std::size_t k = 0; k < s.steps.size(); ++k) {
    const double width = s.steps[k].central ? 2 * s.steps[k].h : s.steps[k].h;
    J.col(static_cast<Eigen::Index>(k)) = (s.plus[k][e][r].mean - s.minus[k][e][r].mean) / width;
  }
  return J;
}

/// One run's NEES as the model predicts it, from the sized posterior and from the whole one (in
/// that order); adds to `spread` what knowing each parameter would take off its prediction,
/// v' C^-1 v / Sigma_kk with v = J Sigma e_k (the part of the widening that k's estimate carries,
/// with its correlations to the others).
std::array<double, 3> run_nees(const RunResidual& run, const MeanJacobian& J, const TrainingUncertainty& u,
                               std::vector<double>& spread) {
  const Matrix3 C = run.cov + run.group_column * run.group_column.transpose() +
                    run.group_column2 * run.group_column2.transpose();
  const Vector3 residual = run.error - run.mean;
  const Eigen::LDLT<Matrix3> own(C);
  auto nees = [&](const Eigen::MatrixXd& sigma, const Eigen::VectorXd& shift) {
    const Vector3 r = residual - J * shift;
    return r.dot(Matrix3(C + J * sigma * J.transpose()).ldlt().solve(r));
  };
  const MeanJacobian JS = J * u.covariance;
  for (std::size_t k = 0; k < spread.size(); ++k) {
    const auto i = static_cast<Eigen::Index>(k);
    const Vector3 v = JS.col(i);
    if (u.covariance(i, i) > 0) spread[k] += v.dot(own.solve(v)) / u.covariance(i, i);
  }
  return {residual.dot(own.solve(residual)), nees(u.covariance_sized, u.shift_sized), nees(u.covariance, u.shift)};
}

}  // namespace

PredictiveCheck predictive_check(const Suite& runs, const TrainingUncertainty& uncertainty) {
  SuiteModel model = uncertainty.model;
  model.measurement_noise = runs.measurement_noise;
  const Sensitivities s = sensitivities(runs, model, uncertainty.names);
  const std::size_t p = uncertainty.names.size();
  PredictiveCheck out;
  for (std::size_t k = 0; k < p; ++k) {
    out.posterior_sd.push_back(std::sqrt(uncertainty.covariance(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k))));
  }
  out.spread.assign(p, 0.0);
  std::array<double, 3> total{};
  double count = 0.0;
  for (std::size_t e = 0; e < s.at.size(); ++e) {
    std::array<double, 3> sum{};
    for (std::size_t r = 0; r < s.at[e].size(); ++r) {
      const std::array<double, 3> nees = run_nees(s.at[e][r], mean_jacobian(s, e, r), uncertainty, out.spread);
      for (std::size_t i = 0; i < 3; ++i) sum[i] += nees[i];
    }
    const double n = std::max<double>(1.0, static_cast<double>(s.at[e].size()));
    out.plugin.push_back(sum[0] / n);
    out.sized.push_back(sum[1] / n);
    out.predictive.push_back(sum[2] / n);
    for (std::size_t i = 0; i < 3; ++i) total[i] += sum[i];
    count += static_cast<double>(s.at[e].size());
  }
  if (count > 0) {
    out.plugin_mean = total[0] / count;
    out.sized_mean = total[1] / count;
    out.predictive_mean = total[2] / count;
    for (double& x : out.spread) x /= count;
  }
  return out;
}

namespace {

/// Menu items as a suite of one run each (its prediction is all the information needs).
Suite menu_suite(const Suite& suite, const std::vector<MenuExperiment>& menu) {
  Suite trial = suite;
  trial.experiments.clear();
  for (const MenuExperiment& m : menu) {
    SuiteExperiment ex;
    ex.name = m.name;
    ex.path = m.path;
    ex.runs.push_back({"1", Vector3::Zero(), {}, {}});
    trial.experiments.push_back(std::move(ex));
  }
  return trial;
}

/// The sensitivities of the menu items, or none where the model cannot predict one of them: a
/// custom expression of it may leave its range there (a noise factor fitted below 1 at the
/// suite's speeds, negative at a faster one), at the fitted values or a difference step away.
/// `why` (when given) receives the error.
std::optional<Sensitivities> menu_sensitivities(const Suite& suite, const std::vector<MenuExperiment>& menu,
                                                const FitResult& fit, std::string* why = nullptr) {
  try {
    return sensitivities(menu_suite(suite, menu), fit.model, fit.names);
  } catch (const InputError& e) {
    if (why) *why = e.what();
    return std::nullopt;
  }
}

}  // namespace

std::vector<NextExperiment> next_experiments(const Suite& suite, const FitResult& fit,
                                             std::vector<UnpredictableExperiment>* unpredictable) {
  std::vector<MenuExperiment> menu = experiment_menu(suite);
  std::optional<Sensitivities> sens = menu_sensitivities(suite, menu, fit);
  if (!sens) {  // the items the model cannot predict, each tried alone, leave the menu
    std::vector<MenuExperiment> predictable;
    for (MenuExperiment& m : menu) {
      std::string why;
      if (menu_sensitivities(suite, {m}, fit, &why)) {
        predictable.push_back(std::move(m));
      } else if (unpredictable) {
        unpredictable->push_back({m.name, why});
      }
    }
    menu = std::move(predictable);
    sens = sensitivities(menu_suite(suite, menu), fit.model, fit.names);
  }
  const Sensitivities& s = *sens;
  const Eigen::MatrixXd now = fisher_information(suite, fit.model, fit.names);
  std::vector<Eigen::MatrixXd> adds;
  Eigen::VectorXd scale = now.diagonal();
  for (std::size_t e = 0; e < menu.size(); ++e) {
    adds.push_back(information_of_experiment(s, e, menu[e].runs));
    scale = scale.cwiseMax(adds.back().diagonal());
  }
  // A relative ridge of 1e-9 keeps a parameter that the suite does not determine at all finite.
  const Eigen::MatrixXd ridge = (1e-9 * scale.cwiseMax(1e-300)).asDiagonal();
  const double base = half_log_det(now + ridge, ridge);
  std::vector<NextExperiment> out;
  for (std::size_t e = 0; e < menu.size(); ++e) {
    const Eigen::MatrixXd after = now + adds[e] + ridge;
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(after);
    NextExperiment next{menu[e], half_log_det(after, ridge), {}};
    next.information_gain -= base;
    const Eigen::MatrixXd cov = ldlt.solve(Eigen::MatrixXd::Identity(after.rows(), after.cols()));
    for (std::size_t k = 0; k < fit.names.size(); ++k) {
      next.expected_stderr.push_back({fit.names[k], std::sqrt(cov(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k)))});
    }
    out.push_back(std::move(next));
  }
  // An item whose gain is not a number (the model's information there is not finite: a fit at
  // an absurd size) cannot be ranked: it leaves the menu, named with why.
  std::vector<std::size_t> order;
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (std::isfinite(out[i].information_gain)) {
      order.push_back(i);
    } else if (unpredictable) {
      unpredictable->push_back({menu[i].name, "its information gain is not a number (the model's information is not finite there)"});
    }
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return out[a].information_gain > out[b].information_gain; });
  std::vector<NextExperiment> ranked;
  std::vector<std::size_t> kept;
  for (std::size_t i : order) {
    const bool same = std::any_of(kept.begin(), kept.end(), [&](std::size_t j) {
      return (adds[i] - adds[j]).norm() <= 1e-6 * adds[j].norm();
    });
    if (same) continue;
    kept.push_back(i);
    ranked.push_back(out[i]);
  }
  return ranked;
}

}  // namespace odomcov
