#include "odomcov/likelihood.hpp"

#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "odomcov/limits.hpp"
#include "odomcov/propagation.hpp"
#include "odomcov/second_order.hpp"
#include "odomcov/statistics.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;

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
  std::vector<std::vector<RunResidual>> out(suite.experiments.size());
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    out[e].resize(ex.runs.size());
    if (!ex.logged) {
      std::vector<double> durations;
      const std::vector<ArcSegment> pieces = model_pieces(ex.path, B, &durations);
      const Prediction p =
          predict_with_order(pieces, durations, model.robot, model.effects, model.order);
      const Vector3 odometry = sampled_end_pose(ex.path, B);
      for (std::size_t r = 0; r < ex.runs.size(); ++r) {
        out[e][r] = {pose_error(ex.runs[r].measured, odometry), p.mean + p.noise_mean,
                     p.cov + meas};
      }
      continue;
    }
    tbb::parallel_for(std::size_t{0}, ex.runs.size(), [&](std::size_t r) {
      const Prediction p =
          predict_with_order(ex.runs[r].pieces, ex.runs[r].durations_s, model.robot,
                             model.effects, model.order);
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


}  // namespace odomcov
