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
///
/// Grouped runs (group_variation, the one effect that correlates runs): the runs of one group
/// share a standard-normal constant z_g, and run i's error is
///   e_i = mean_i + group_column_i z_g + w_i,   w_i ~ N(0, cov_i) independent,
/// so a group's runs have the joint covariance blockdiag(cov_i) + U U^T, U the stacked columns
/// (rank one). group_column is sd times the first-order sensitivity of the run's predicted mean
/// to the varied parameter (a forward difference of the systematic mean); it is zero without
/// group_variation, and then the runs are independent.
struct RunResidual {
  Vector3 error = Vector3::Zero();
  Vector3 mean = Vector3::Zero();
  Matrix3 cov = Matrix3::Zero();
  Vector3 group_column = Vector3::Zero();
  int group = -1;  // index of the run's group (group_key) in order of first appearance
};

/// Residuals of every run of every experiment (runs with logs are predicted one by one, in
/// parallel), with each run's group and group column.
std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model);

/// "" when every experiment's order-2 prediction stays within kMaxSecondOrderPieces
/// (limits.hpp; its cost is quadratic), else which experiment exceeds it. With `order` 1 always
/// "". compare, fit and diagnose at order 2 need it empty (the CLI refuses such a suite first).
std::string second_order_problem(const Suite& suite, int order);

/// The grouped likelihood in its sequential form (the chain rule over each group's runs, in
/// suite order): each run's predictive distribution given the earlier runs of its group. For a
/// group with z_g ~ N(m, v) after the earlier runs, run i is predicted as
///   N(mean_i + u_i m, cov_i + v u_i u_i^T),
/// then (m, v) are updated with the run's residual r_i = e_i - mean_i - u_i m by
/// Sherman-Morrison: with a = u^T cov^-1 u and b = u^T cov^-1 r,
///   m += v b / (1 + v a),  v /= 1 + v a.
/// The result has zero group columns and independent runs: summing its runs' Gaussian
/// log-densities gives the joint log-likelihood of every group exactly (the matrix determinant
/// lemma: ln det(cov + v u u^T) = ln det cov + ln(1 + v a)) in O(runs), and whitening each run
/// by its own covariance whitens the groups jointly (block Cholesky), which is how compare
/// tests grouped runs. Without group columns the residuals come back unchanged.
std::vector<std::vector<RunResidual>> condition_on_groups(
    const std::vector<std::vector<RunResidual>>& residuals);

/// Each run's prediction on its own, the between-group spread included: cov_i + u_i u_i^T (a
/// run of a held-out group, of which no run has been seen). Zero group columns.
std::vector<std::vector<RunResidual>> marginal(const std::vector<std::vector<RunResidual>>& residuals);

/// Each run's term of the log-likelihood, in order (experiment by experiment): the Gaussian
/// log-density of its error given the earlier runs of its group (condition_on_groups; they sum
/// to the grouped joint log-likelihood), or with `scatter` its term of scatter_log_likelihood.
std::vector<double> run_log_likelihoods(const std::vector<std::vector<RunResidual>>& residuals,
                                        bool scatter);

/// Sum over runs of the Gaussian log-density of the error under its prediction: the joint
/// log-likelihood, runs of one group correlated through their group columns.
double log_likelihood(const std::vector<std::vector<RunResidual>>& residuals);

/// The scatter part of the log-likelihood: only the spread of each experiment's runs about
/// their own mean counts (Wishart likelihood of the within-experiment scatter, [Anderson03]
/// §7.2): for residuals r_i = e_i - mu_i,
///   sum_i -1/2 (r_i - r_bar)' Sigma_i^-1 (r_i - r_bar) - 1/2 ((n-1)/n) ln det(2 pi Sigma_i).
/// A misfit of the mean does not enter, so a variance effect cannot gain by absorbing one.
/// Group columns do not enter either: a group's shared offset moves an experiment's runs
/// together, which the experiment's own mean removes (exactly when the runs share one path).
double scatter_log_likelihood(const std::vector<std::vector<RunResidual>>& residuals);

}  // namespace odomcov
