#include "odomcov/likelihood.hpp"

#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <limits>

#include "odomcov/propagation.hpp"
#include "odomcov/second_order.hpp"
#include "odomcov/statistics.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;

}  // namespace

std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model) {
  const double B = model.robot.wheelbase_m;
  const Matrix3 meas = model.measurement_noise.covariance();
  std::vector<std::vector<RunResidual>> out(suite.experiments.size());
  // Every unit of work: a planned-path experiment (one prediction serves all its runs) or one
  // logged run. They run in parallel over the whole suite (most logged experiments are single
  // runs, so a loop per experiment would leave cores idle).
  std::vector<std::pair<std::size_t, std::size_t>> work;
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
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
    if (ex.logged) {
      const Prediction p = predict_with_order(ex.runs[r].pieces, ex.runs[r].durations_s,
                                              model.robot, model.effects, model.order);
      out[e][r] = {pose_error(ex.runs[r].measured, p.odometry_end_pose), p.mean + p.noise_mean,
                   p.cov + meas};
      return;
    }
    std::vector<double> durations;
    const std::vector<ArcSegment> pieces = model_pieces(ex.path, B, &durations);
    const Prediction p = predict_with_order(pieces, durations, model.robot, model.effects, model.order);
    const Vector3 odometry = sampled_end_pose(ex.path, B);
    for (std::size_t i = 0; i < ex.runs.size(); ++i) {
      out[e][i] = {pose_error(ex.runs[i].measured, odometry), p.mean + p.noise_mean, p.cov + meas};
    }
  }, tbb::simple_partitioner());
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


}  // namespace odomcov
