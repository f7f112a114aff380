// The likelihood of measured runs under a model: each run's error against its predicted mean and
// covariance (measurement noise included), and the Gaussian log-likelihood and its scatter part.
#pragma once

#include <string>
#include <vector>

#include "odomcov/suite.hpp"

namespace odomcov {

/// One run set against the model: its error (measured - odometry at the model's wheelbase) and
/// the predicted mean and covariance, measurement noise included, of the model's order
/// (SuiteModel::order; predict_with_order: logged runs take the order-2 correction on
/// coarsened pieces). The predicted mean is the systematic mean plus the noise-induced mean.
struct RunResidual {
  Vector3 error = Vector3::Zero();
  Vector3 mean = Vector3::Zero();
  Matrix3 cov = Matrix3::Zero();
};

/// Residuals of every run of every experiment (runs with logs are predicted one by one, in
/// parallel).
/// "" when every experiment's order-2 prediction stays within kMaxSecondOrderPieces
/// (limits.hpp; its cost is quadratic), else which experiment exceeds it. With `order` 1 always
/// "". compare, fit and diagnose at order 2 need it empty (the CLI refuses such a suite first).
std::string second_order_problem(const Suite& suite, int order);

std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model);

/// Each run's term of the log-likelihood, in order (experiment by experiment): the Gaussian
/// log-density of its error, or with `scatter` its term of scatter_log_likelihood.
std::vector<double> run_log_likelihoods(const std::vector<std::vector<RunResidual>>& residuals,
                                        bool scatter);

/// Sum over runs of the Gaussian log-density of the error under its prediction.
double log_likelihood(const std::vector<std::vector<RunResidual>>& residuals);

/// The scatter part of the log-likelihood: only the spread of each experiment's runs about
/// their own mean counts (Wishart likelihood of the within-experiment scatter, [Anderson03]
/// §7.2): for residuals r_i = e_i - mu_i,
///   sum_i -1/2 (r_i - r_bar)' Sigma_i^-1 (r_i - r_bar) - 1/2 ((n-1)/n) ln det(2 pi Sigma_i).
/// A misfit of the mean does not enter, so a variance effect cannot gain by absorbing one.
double scatter_log_likelihood(const std::vector<std::vector<RunResidual>>& residuals);

}  // namespace odomcov
