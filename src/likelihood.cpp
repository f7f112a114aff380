#include "odomcov/likelihood.hpp"

#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>

#include "odomcov/limits.hpp"
#include "odomcov/propagation.hpp"
#include "odomcov/second_order.hpp"
#include "odomcov/statistics.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;

/// group_variation's column for one run: sd times the forward difference of the systematic
/// mean (exact for the perturbed path at any order) in the varied parameter, from `mean`, the
/// mean at the parameter's value. A logged run passes its prediction's: on fine pieces
/// predict_with_order's mean is predict's, bit for bit predict_mean's (on pieces it cannot
/// coarsen, the order-2 model's, the same up to rounding, ~1e-16 relative). The step is 1e-7
/// of the parameter's size (at least 1e-7): truncation ~h |mu''/mu'| ~ 1e-7 of the column,
/// rounding ~eps |mu|/(h |mu'|) far below. One mean-only propagation per run.
Vector3 group_column(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations,
                     const Robot& robot, const EffectList& effects, const GroupTarget& target,
                     const Vector3& mean) {
  if (!target.present || target.sd == 0.0) return Vector3::Zero();
  const double value = effects[target.effect].values[target.parameter];
  const double h = 1e-7 * std::max(1.0, std::abs(value));
  EffectList shifted = effects;
  shifted[target.effect].values[target.parameter] = value + h;
  const Vector3 up = predict_mean(pieces, durations, robot, shifted);
  return target.sd * (up - mean) / h;
}

}  // namespace

std::string second_order_problem(const Suite& suite, int order) {
  if (order != 2) return "";
  const double B = suite.robot.wheelbase_m;
  for (const SuiteExperiment& ex : suite.experiments) {
    std::size_t most = 0;
    if (!ex.logged) most = second_order_piece_count(model_pieces(ex.path, B), B);
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

std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model) {
  const double B = model.robot.wheelbase_m;
  const Matrix3 meas = model.measurement_noise.covariance();
  const GroupTarget target = group_target(model.effects);
  std::map<std::string, int> groups;
  std::vector<std::vector<RunResidual>> out(suite.experiments.size());
  // Every unit of work: a planned-path experiment (one prediction serves all its runs) or one
  // logged run. They run in parallel over the whole suite (most logged experiments are single
  // runs, so a loop per experiment would leave cores idle).
  // Group indices are assigned serially first (in experiment order), so they do not depend on
  // the thread schedule.
  std::vector<std::pair<std::size_t, std::size_t>> work;
  std::vector<int> group_of(suite.experiments.size());
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    group_of[e] = groups.emplace(group_key(ex), static_cast<int>(groups.size())).first->second;
    out[e].resize(ex.runs.size());
    if (!ex.logged) {
      work.emplace_back(e, 0);
      continue;
    }
    for (std::size_t r = 0; r < ex.runs.size(); ++r) work.emplace_back(e, r);
  }
  tbb::parallel_for(std::size_t{0}, work.size(), [&](std::size_t w) {
    const auto [e, r] = work[w];
    const SuiteExperiment& ex = suite.experiments[e];
    const int group = group_of[e];
    if (ex.logged) {
      const SuiteRun& run = ex.runs[r];
      const Prediction p =
          predict_with_order(run.pieces, run.durations_s, model.robot, model.effects, model.order);
      out[e][r] = {pose_error(run.measured, p.odometry_end_pose), p.mean + p.noise_mean,
                   p.cov + meas,
                   group_column(run.pieces, run.durations_s, model.robot, model.effects, target, p.mean),
                   group};
      return;
    }
    std::vector<double> durations;
    const std::vector<ArcSegment> pieces = model_pieces(ex.path, B, &durations);
    const Prediction p = predict_with_order(pieces, durations, model.robot, model.effects, model.order);
    const Vector3 column =
        group_column(pieces, durations, model.robot, model.effects, target,
                     target.present ? predict_mean(pieces, durations, model.robot, model.effects)
                                    : Vector3::Zero());
    const Vector3 odometry = sampled_end_pose(ex.path, B);
    for (std::size_t i = 0; i < ex.runs.size(); ++i) {
      out[e][i] = {pose_error(ex.runs[i].measured, odometry), p.mean + p.noise_mean, p.cov + meas,
                   column, group};
    }
  }, tbb::simple_partitioner());
  return out;
}

std::vector<std::vector<RunResidual>> condition_on_groups(
    const std::vector<std::vector<RunResidual>>& res) {
  struct Posterior {
    double m = 0.0, v = 1.0;  // of the group's standard-normal constant
  };
  std::map<int, Posterior> posteriors;
  std::vector<std::vector<RunResidual>> out = res;
  for (auto& ex : out) {
    for (RunResidual& r : ex) {
      if (r.group_column.isZero(0.0)) continue;
      const Vector3 u = r.group_column;
      Posterior& g = posteriors[r.group];
      const Eigen::LLT<Matrix3> llt(r.cov);
      const bool whitens = llt.info() == Eigen::Success && r.cov.allFinite() && u.allFinite();
      r.mean += u * g.m;
      const Vector3 residual = r.error - r.mean;
      r.cov += g.v * u * u.transpose();
      r.group_column.setZero();
      if (!whitens || !residual.allFinite()) continue;  // compare calls such a run untestable
      const Vector3 a = llt.matrixL().solve(u), b = llt.matrixL().solve(residual);
      const double gain = g.v / (1.0 + g.v * a.squaredNorm());
      g.m += gain * a.dot(b);
      g.v = gain;
    }
  }
  return out;
}

std::vector<std::vector<RunResidual>> marginal(const std::vector<std::vector<RunResidual>>& res) {
  std::vector<std::vector<RunResidual>> out = res;
  for (auto& ex : out) {
    for (RunResidual& r : ex) {
      r.cov += r.group_column * r.group_column.transpose();
      r.group_column.setZero();
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


}  // namespace odomcov
