// The likelihood of measured runs under a model: each run's error against its predicted mean and
// covariance (measurement noise included), and the Gaussian log-likelihood and its scatter part.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "odomcov/engine/second_order.hpp"
#include "odomcov/measurement/suite.hpp"

namespace odomcov {

/// One run set against the model: its error (measured - odometry at the model's wheelbase) and
/// the predicted mean and covariance, measurement noise included, of the model's order
/// (SuiteModel::order; predict_with_order: logged runs take the order-2 correction on
/// coarsened pieces). The predicted mean is the systematic mean plus the noise-induced mean.
///
/// Grouped runs (group_variation, the one effect that correlates runs): the runs of one group
/// share a draw z_g ~ N(0, 1) of the varied parameter, value + sd z_g, and run i's error is, to
/// second order in the draw,
///   e_i = mean_i + group_column_i z_g + group_column2_i q_g + w_i,   w_i ~ N(0, cov_i),
/// with q_g = (z_g^2 - 1) / sqrt(2) (unit variance, uncorrelated with z_g), taken as Gaussian:
/// a group's runs have the joint covariance blockdiag(cov_i) + U U^T, U the stacked [columns]
/// (rank two). group_column is sd times the sensitivity of the run's systematic mean to the
/// varied parameter, group_column2 sd^2/sqrt(2) times its curvature, and mean includes the
/// draw's average sd^2/2 times the curvature (Gauss-Hermite points value, value +- sqrt(3) sd).
/// Both are zero without group_variation, and then the runs are independent.
struct RunResidual {
  Vector3 error = Vector3::Zero();
  Vector3 mean = Vector3::Zero();
  Matrix3 cov = Matrix3::Zero();
  Vector3 group_column = Vector3::Zero();
  int group = -1;  // index of the run's group (group_key) in order of first appearance
  Vector3 group_column2 = Vector3::Zero();
  /// The noise-induced part of `mean` (Prediction::noise_mean): the mean of the part of the error
  /// that is quadratic in the heading noise, the measure of how far from Gaussian it is
  /// (compare's choice of calibration).
  Vector3 noise_mean = Vector3::Zero();
};

/// Residuals of every run of every experiment (runs with logs are predicted one by one, in
/// parallel), with each run's group and group column. A planned path's runs share one
/// prediction, unless an effect of the model uses the absolute heading (effect_needs): then
/// each run is predicted from its own start heading (SuiteRun::heading0_rad), as logged runs
/// always are.
/// `coarse`, when given, is coarsen_logged_runs(suite): the logged runs' coarse pieces, made
/// once for every evaluation (the same numbers as without). `only`, when given, marks the
/// experiments to compute (one flag per experiment); the others are left with no runs. A run's
/// residual does not depend on the others', and group indices count every experiment, so the
/// marked ones get the same numbers as without.
///
/// `predictions`, when given, keeps each run's prediction (predict_parts: before the
/// external reference's view, the group terms and the measurement noise) from one call to the
/// next: a run whose slot holds one reuses it, and a run predicted here fills its slot (a
/// planned path's runs that share one prediction keep it in their first run's slot). The slots
/// must come from models that move the robot alike: the same robot, order and effects, with at
/// most the values of measurement-only effects (reference_offset) and of group_variation, and the
/// measurement noise, changed (they enter after the prediction). A fit of a reference offset or
/// a group's sd then propagates no run again.
using CoarseRuns = std::vector<std::vector<CoarsePieces>>;
using RunPredictions = std::vector<std::vector<std::optional<PredictionParts>>>;
std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model,
                                                const CoarseRuns* coarse = nullptr,
                                                const std::vector<bool>* only = nullptr,
                                                RunPredictions* predictions = nullptr);

/// Every logged run's pieces coarsened at the suite's wheelbase (coarsen: what the order-2
/// correction is taken on), indexed as the suite's experiments and runs; planned-path
/// experiments get no entries.
CoarseRuns coarsen_logged_runs(const Suite& suite);

/// "" when every experiment's order-2 prediction stays within kMaxSecondOrderPieces
/// (limits.hpp; its cost is quadratic), else which experiment exceeds it, for the pieces of the
/// suite's own model (path_model_pieces). With `order` 1 always "". compare, fit and diagnose
/// at order 2 need it empty (the CLI refuses such a suite first).
std::string second_order_problem(const Suite& suite, int order);

/// The grouped likelihood in its sequential form (the chain rule over each group's runs, in
/// suite order): each run's predictive distribution given the earlier runs of its group. For a
/// group with (z_g, q_g) ~ N(m, V) after the earlier runs (m 2-vector, V 2x2), with
/// U_i = [group_column_i group_column2_i], run i is predicted as
///   N(mean_i + U_i m, cov_i + U_i V U_i^T),
/// then (m, V) are updated with the run's residual r_i = e_i - mean_i - U_i m by Woodbury:
/// with A = U^T cov^-1 U (2x2) and b = U^T cov^-1 r,
///   V <- (I + V A)^-1 V,  m += V b  (the new V; with one column, Sherman-Morrison's scalars).
/// The result has zero group columns and independent runs: summing its runs' Gaussian
/// log-densities gives the joint log-likelihood of every group exactly (the matrix determinant
/// lemma: ln det(cov + U V U^T) = ln det cov + ln det(I + V A)) in O(runs), and whitening each run
/// by its own covariance whitens the groups jointly (block Cholesky), which is how compare
/// tests grouped runs. Without group columns the residuals come back unchanged.
std::vector<std::vector<RunResidual>> condition_on_groups(
    const std::vector<std::vector<RunResidual>>& residuals);

/// Each run's prediction on its own, the between-group spread included: cov_i + U_i U_i^T (a
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

/// How far n residuals r_i scatter about their own mean beyond what their covariances Sigma_i
/// predict: W = sum_i d_i' Sigma_i^-1 d_i (d_i = r_i - r_bar) over its expectation under the
/// model, sum_i [3 (1 - 2/n) + tr(Sigma_i^-1 Sigma_bar) / n] with Sigma_bar the mean covariance
/// (3 (n - 1) when the runs share one covariance). Nothing for fewer than two runs, a covariance
/// that is not positive definite or a residual that is not finite.
std::optional<double> scatter_ratio(const std::vector<Vector3>& r, const std::vector<Matrix3>& cov);

/// How far the experiments' mean errors scatter beyond what the model predicts for them
/// (mean_dispersion).
struct MeanDispersion {
  double phi = 1.0;  // at least 1
  int dof = 0;       // 3 m - p; 0: none estimated
};

/// The Pearson statistic of the experiments' mean residuals over its degrees of freedom:
/// phi = sum_e r_e' C_e^-1 r_e / (3 m - p), r_e the mean of experiment e's residuals and C_e
/// = sum_i Sigma_i / n^2 its predicted covariance, each run conditioned on the earlier runs of
/// its group (condition_on_groups: independent under the model), over the m experiments and
/// the p systematic parameters fitted; 1 when smaller, or without degrees of freedom. A
/// systematic misfit the model does not have scatters the experiments' means as a variance
/// would, so phi is the overdispersion of the quasi-likelihood [McCullagh89, §9.2]: under it a
/// likelihood-ratio gain in the mean is phi times too large.
MeanDispersion mean_dispersion(const std::vector<std::vector<RunResidual>>& residuals, std::size_t fitted);

}  // namespace odomcov
