#include "odomcov/measurement/likelihood.hpp"

#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "odomcov/base/error.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/second_order.hpp"
#include "odomcov/engine/statistics.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;

/// group_variation's terms for one run, to second order in the group's draw z ~ N(0, 1):
///   f(value + sd z) = f + shift + column z + column2 q,   q = (z^2 - 1) / sqrt(2),
/// with f the systematic mean (exact for the perturbed path at any order), shift = sd^2 f''/2
/// (the draw's average of the curvature: a line that a drawn Ed turns by theta is shorter by
/// d theta^2 / 6 whatever the sign), column = sd f' and column2 = sd^2 f'' / sqrt(2). q has unit
/// variance and is uncorrelated with z, and the runs of a group share it as they share z. From
/// the three points value and value +- h, h = sqrt(3) sd (Gauss-Hermite: the column is then
/// E[f z] and the shift E[f] - f exactly for polynomials of degree 3 and 5), h kept within half
/// the distance to the parameter's bounds (at a bound, none: no terms). f at the value is
/// `mean`: a logged run passes its
/// prediction's (on fine pieces predict_with_order's mean is predict_mean's bit for bit; on
/// pieces it cannot coarsen, the order-2 model's, the same up to rounding, ~1e-16 relative),
/// and its odometry end pose, which the shifted parameter does not change. Two mean-only
/// propagations per run, in one walk over its pieces where the effects allow (predict_means).
struct GroupTerms {
  Vector3 shift = Vector3::Zero(), column = Vector3::Zero(), column2 = Vector3::Zero();
};

GroupTerms group_terms(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations,
                       const Robot& robot, const EffectList& effects, const GroupTarget& target,
                       const Vector3& mid, const Vector3* odometry_end_pose = nullptr,
                       double heading0_rad = 0.0) {
  if (!target.present || target.sd == 0.0) return {};
  const double value = effects[target.effect].values[target.parameter];
  const EffectParameterInfo& p = info_of(effects[target.effect])->parameters[target.parameter];
  const double h = std::min({std::sqrt(3.0) * target.sd, 0.5 * (value - p.lower), 0.5 * (p.upper - value)});
  // A value on a bound of its range (backlash at 0) cannot vary to either side: no terms, as
  // with sd = 0, rather than differences over a zero step.
  if (!(h > 0.0)) return {};
  std::vector<EffectList> shifted(2, effects);
  shifted[0][target.effect].values[target.parameter] = value + h;
  shifted[1][target.effect].values[target.parameter] = value - h;
  const std::vector<Vector3> means =
      predict_means(pieces, durations, robot, shifted, odometry_end_pose, heading0_rad);
  const Vector3& up = means[0];
  const Vector3& down = means[1];
  const double sd2_h2 = target.sd * target.sd / (h * h);  // 1/3 unless h is cut by a bound
  const Vector3 curvature = up + down - 2.0 * mid;        // h^2 f''
  return {0.5 * sd2_h2 * curvature, target.sd * (up - down) / (2.0 * h),
          sd2_h2 * curvature / std::sqrt(2.0)};
}

/// What the reference sees of the parts in `kept` when it holds them, else of predict()'s,
/// stored there when given.
template <class Predict>
Prediction kept_or_predicted(std::optional<PredictionParts>* kept, const SuiteModel& model, Predict&& predict) {
  if (kept == nullptr) return measured(predict(), model.robot, model.effects);
  if (!kept->has_value()) kept->emplace(predict());
  return measured(**kept, model.robot, model.effects);
}

/// One planned path's prediction for a run that starts at `heading0_rad`, with its group terms:
/// the residual of each run of `runs` (all of the experiment's, or one).
/// `kept` (when not nullptr) is the prediction's slot (residuals' `predictions`).
void predict_path_runs(const SuiteExperiment& ex, const SuiteModel& model, const GroupTarget& target,
                       const Matrix3& meas, int group, double heading0_rad, std::size_t first,
                       std::size_t count, std::vector<RunResidual>& out, std::optional<PredictionParts>* kept) {
  const double B = model.robot.wheelbase_m;
  std::vector<double> durations;
  const std::vector<ArcSegment> pieces = path_model_pieces(ex.path, B, model.effects, &durations);
  const Prediction p = kept_or_predicted(kept, model, [&] {
    return predict_parts(pieces, durations, model.robot, model.effects, model.order, heading0_rad);
  });
  const GroupTerms g = group_terms(
      pieces, durations, model.robot, model.effects, target,
      target.present ? predict_mean(pieces, durations, model.robot, model.effects, nullptr, heading0_rad)
                     : Vector3::Zero(),
      nullptr, heading0_rad);
  const Vector3 odometry = sampled_end_pose(ex.path, B);
  for (std::size_t i = first; i < first + count; ++i) {
    out[i] = {pose_error(ex.runs[i].measured, odometry), p.mean + p.noise_mean + g.shift, p.cov + meas,
              g.column, group, g.column2, p.noise_mean};
  }
}

/// One slot per run of every experiment (residuals' `predictions`); what they hold stays.
void size_slots(RunPredictions& slots, const Suite& suite) {
  slots.resize(suite.experiments.size());
  for (std::size_t e = 0; e < slots.size(); ++e) slots[e].resize(suite.experiments[e].runs.size());
}

/// A logged run's residual (its prediction kept in `kept` when not nullptr).
void predict_logged_run(const SuiteRun& run, const SuiteModel& model, const GroupTarget& target,
                        const Matrix3& meas, int group, const CoarsePieces* coarse,
                        std::optional<PredictionParts>* kept, RunResidual& out) {
  const Prediction p = kept_or_predicted(kept, model, [&] {
    return predict_parts(run.pieces, run.durations_s, model.robot, model.effects, model.order, run.heading0_rad,
                         coarse);
  });
  const GroupTerms g = group_terms(run.pieces, run.durations_s, model.robot, model.effects, target, p.mean,
                                   &p.odometry_end_pose, run.heading0_rad);
  out = {pose_error(run.measured, p.odometry_end_pose), p.mean + p.noise_mean + g.shift, p.cov + meas,
         g.column, group, g.column2, p.noise_mean};
}

/// One unit of residuals' work: run r of experiment ex (logged, or of a path predicted from the
/// run's start heading: `per_run`), or every run of a planned path. The engine's errors know no
/// file (order 2's piece limit, met as the model's effects cut the pieces): one is raised again
/// naming the suite and the experiment it is about.
void predict_unit(const Suite& suite, const SuiteExperiment& ex, const SuiteModel& model, const GroupTarget& target,
                  const Matrix3& meas, int group, bool per_run, std::size_t r, const CoarsePieces* coarse,
                  std::optional<PredictionParts>* kept, std::vector<RunResidual>& out) {
  try {
    if (!ex.logged) {
      const std::size_t count = per_run ? 1 : ex.runs.size();
      predict_path_runs(ex, model, target, meas, group, per_run ? ex.runs[r].heading0_rad : 0.0, r, count, out, kept);
      return;
    }
    predict_logged_run(ex.runs[r], model, target, meas, group, coarse, kept, out[r]);
  } catch (const InputError& e) {
    if (!e.file().empty()) throw;
    throw InputError(suite.file, 0, e.key(), ex.name + ": " + e.message());
  }
}

}  // namespace

std::string second_order_problem(const Suite& suite, int order) {
  if (order != 2) return "";
  const double B = suite.robot.wheelbase_m;
  for (const SuiteExperiment& ex : suite.experiments) {
    std::size_t most = 0;
    if (!ex.logged) {
      std::vector<double> durations;
      const std::vector<ArcSegment> pieces = path_model_pieces(ex.path, B, suite.model_effects, &durations);
      most = second_order_piece_count(pieces, durations, B, suite.model_effects);
    }
    for (const SuiteRun& run : ex.logged ? ex.runs : std::vector<SuiteRun>{}) {
      most = std::max(most, second_order_piece_count(coarsen_pieces(run.pieces, B), B));
    }
    if (most > kMaxSecondOrderPieces) {
      return ex.name + ": order 2 needs " + std::to_string(most) +
             " quadrature pieces here, above the limit " + std::to_string(kMaxSecondOrderPieces) +
             " (its cost is quadratic); use --order 1";
    }
  }
  return "";
}

CoarseRuns coarsen_logged_runs(const Suite& suite) {
  CoarseRuns out(suite.experiments.size());
  std::vector<std::pair<std::size_t, std::size_t>> runs;  // (experiment, run), in parallel below
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    if (!ex.logged) continue;
    out[e].resize(ex.runs.size());
    for (std::size_t r = 0; r < ex.runs.size(); ++r) runs.emplace_back(e, r);
  }
  tbb::parallel_for(std::size_t{0}, runs.size(), [&](std::size_t i) {
    const auto [e, r] = runs[i];
    const SuiteRun& run = suite.experiments[e].runs[r];
    out[e][r] = coarsen(run.pieces, run.durations_s, suite.robot.wheelbase_m);
  });
  return out;
}

std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model,
                                                const CoarseRuns* coarse, const std::vector<bool>* only,
                                                RunPredictions* predictions) {
  const Matrix3 meas = model.measurement_noise.covariance();
  const GroupTarget target = group_target(model.effects);
  // With an effect that uses the absolute heading every run is predicted from its own start
  // heading; else one prediction serves all the runs of a planned path (the fast common case).
  const bool per_run = effect_needs(model.effects).start_heading;
  std::map<std::string, int> groups;
  std::vector<std::vector<RunResidual>> out(suite.experiments.size());
  // Every unit of work: a planned-path experiment (one prediction serves all its runs) or one
  // run (logged, or of a path whose prediction depends on the run's start heading). They run in
  // parallel over the whole suite (most logged experiments are single runs, so a loop per
  // experiment would leave cores idle).
  // Group indices are assigned serially first (in experiment order), so they do not depend on
  // the thread schedule.
  std::vector<std::pair<std::size_t, std::size_t>> work;
  std::vector<int> group_of(suite.experiments.size());
  if (predictions != nullptr) size_slots(*predictions, suite);  // serially: the parallel loop fills its own slots
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    group_of[e] = groups.emplace(group_key(ex), static_cast<int>(groups.size())).first->second;
    if (only != nullptr && !(e < only->size() && (*only)[e])) continue;
    out[e].resize(ex.runs.size());
    if (!ex.logged && !per_run) {
      work.emplace_back(e, 0);
      continue;
    }
    for (std::size_t r = 0; r < ex.runs.size(); ++r) work.emplace_back(e, r);
  }
  // The longest logged runs first, so that no core is left with a long one at the end (the
  // results go to their own slots: the order changes no number).
  auto length = [&](const std::pair<std::size_t, std::size_t>& w) {
    const SuiteExperiment& ex = suite.experiments[w.first];
    return ex.logged ? ex.runs[w.second].pieces.size() : std::size_t{0};
  };
  std::stable_sort(work.begin(), work.end(), [&](const auto& a, const auto& b) { return length(a) > length(b); });
  tbb::parallel_for(std::size_t{0}, work.size(), [&](std::size_t w) {
    const std::size_t e = work[w].first, r = work[w].second;
    const SuiteExperiment& ex = suite.experiments[e];
    const int group = group_of[e];
    std::optional<PredictionParts>* kept = predictions != nullptr ? &(*predictions)[e][r] : nullptr;
    predict_unit(suite, ex, model, target, meas, group, per_run, r, coarse != nullptr ? &(*coarse)[e][r] : nullptr,
                 kept, out[e]);
  }, tbb::simple_partitioner());
  return out;
}

std::vector<std::vector<RunResidual>> condition_on_groups(
    const std::vector<std::vector<RunResidual>>& res) {
  struct Posterior {
    Eigen::Vector2d m = Eigen::Vector2d::Zero();  // of the group's constants (z, q)
    Eigen::Matrix2d v = Eigen::Matrix2d::Identity();
  };
  std::map<int, Posterior> posteriors;
  std::vector<std::vector<RunResidual>> out = res;
  for (auto& ex : out) {
    for (RunResidual& r : ex) {
      if (r.group_column.isZero(0.0) && r.group_column2.isZero(0.0)) continue;
      Eigen::Matrix<double, 3, 2> U;
      U << r.group_column, r.group_column2;
      Posterior& g = posteriors[r.group];
      const Eigen::LLT<Matrix3> llt(r.cov);
      const bool whitens = llt.info() == Eigen::Success && r.cov.allFinite() && U.allFinite();
      r.mean += U * g.m;
      const Vector3 residual = r.error - r.mean;
      r.cov += U * g.v * U.transpose();
      r.group_column.setZero();
      r.group_column2.setZero();
      if (!whitens || !residual.allFinite()) continue;  // compare calls such a run untestable
      const Eigen::Matrix<double, 3, 2> A = llt.matrixL().solve(U);
      const Vector3 b = llt.matrixL().solve(residual);
      // (v^-1 + A'A)^-1 = (I + v A'A)^-1 v: the 2x2 Woodbury step (rank one: the scalar gain).
      const Eigen::Matrix2d gain =
          (Eigen::Matrix2d::Identity() + g.v * A.transpose() * A).partialPivLu().solve(g.v);
      g.m += gain * (A.transpose() * b);
      g.v = 0.5 * (gain + gain.transpose());
    }
  }
  return out;
}

std::vector<std::vector<RunResidual>> marginal(const std::vector<std::vector<RunResidual>>& res) {
  std::vector<std::vector<RunResidual>> out = res;
  for (auto& ex : out) {
    for (RunResidual& r : ex) {
      r.cov += r.group_column * r.group_column.transpose() +
               r.group_column2 * r.group_column2.transpose();
      r.group_column.setZero();
      r.group_column2.setZero();
    }
  }
  return out;
}

std::vector<double> run_log_likelihoods(const std::vector<std::vector<RunResidual>>& res,
                                        bool scatter) {
  std::vector<double> out;
  if (!scatter) {
    for (const auto& ex : condition_on_groups(res)) {
      for (const RunResidual& r : ex) out.push_back(gaussian_log_density(r.error, r.mean, r.cov));
    }
    return out;
  }
  for (const auto& ex : res) {
    const double n = static_cast<double>(ex.size());
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

std::optional<double> scatter_ratio(const std::vector<Vector3>& r, const std::vector<Matrix3>& cov) {
  const std::size_t n = r.size();
  if (n < 2 || cov.size() != n) return std::nullopt;
  const double nd = static_cast<double>(n);
  Vector3 mean = Vector3::Zero();
  Matrix3 cov_mean = Matrix3::Zero();
  for (std::size_t i = 0; i < n; ++i) mean += r[i] / nd, cov_mean += cov[i] / nd;
  double w = 0.0, expected = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::LDLT<Matrix3> ldlt(cov[i]);
    const Vector3 d = r[i] - mean;
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0) || !d.allFinite()) {
      return std::nullopt;
    }
    w += d.dot(ldlt.solve(d));
    expected += kDim * (1.0 - 2.0 / nd) + ldlt.solve(cov_mean).trace() / nd;
  }
  if (!(expected > 0)) return std::nullopt;
  return w / expected;
}

MeanDispersion mean_dispersion(const std::vector<std::vector<RunResidual>>& residuals, std::size_t fitted) {
  double pearson = 0.0;
  int terms = 0;
  for (const std::vector<RunResidual>& runs : condition_on_groups(residuals)) {
    if (runs.empty()) continue;
    const double n = static_cast<double>(runs.size());
    Vector3 r = Vector3::Zero();
    Matrix3 C = Matrix3::Zero();
    for (const RunResidual& x : runs) r += (x.error - x.mean) / n, C += x.cov / (n * n);
    const Eigen::LDLT<Matrix3> ldlt(C);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0) || !r.allFinite()) continue;
    pearson += r.dot(ldlt.solve(r));
    terms += 3;
  }
  const int dof = terms - static_cast<int>(fitted);
  if (dof <= 0) return {};
  return {std::max(1.0, pearson / dof), dof};
}

}  // namespace odomcov
