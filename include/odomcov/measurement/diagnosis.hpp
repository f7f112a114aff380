// diagnose: which physical effect is the model missing? Every candidate is fitted by maximum
// likelihood; the best is named when it is significant after the multiple-comparison
// correction. The verdict is honest: the data are "explained" only when compare finds the final
// model consistent; otherwise diagnose says what the remaining misfit lines up with.
#pragma once

#include <atomic>
#include <limits>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/measurement/cross_validation.hpp"
#include "odomcov/measurement/odometry_correction.hpp"
#include "odomcov/measurement/residual_features.hpp"

namespace odomcov {

/// One kind of diagnose candidate: every catalogue effect (from its EffectInfo) and the robot
/// candidates (wheel_noise_level), all described in src/effects/ so that diagnose holds no
/// effect's name.
struct CandidateType {
  /// The effect's name, kWheelNoiseLevel, or "group_variation(E.p)" for a group candidate.
  std::string name;
  /// The effect whose spec holds the candidate's result (group_variation for a group candidate;
  /// "" for a robot candidate).
  std::string effect;
  std::string physics, signature;  // plain words (EffectInfo)
  bool systematic = false;         // judged on the full likelihood, else on its scatter part
  /// The fit names it moves: "<effect>.<parameter>", or robot parameters ("k_left").
  std::vector<std::string> fitted;
  /// True when every fitted parameter's "no effect" value is the closed edge of its range (the
  /// LRT is then a 50:50 chi^2 mixture [Self87]).
  bool on_boundary = false;
  bool robot = false;  // moves robot parameters (its YAML is the robot line), not an effect
  std::vector<std::string> contains;  // EffectInfo::contains
  CandidateCompletion complete = nullptr;
  /// Specs added to the model before the fit, at their starting values (a user candidate's
  /// given spec; a group candidate's varied effect when new, and group_variation). Empty: the
  /// fit adds the effect with its fitted parameters at their neutral values.
  EffectList start{};
};
/// The candidate of one effect (catalogue or custom), from its EffectInfo.
CandidateType effect_candidate(const EffectInfo& info);
/// Every candidate kind: the catalogue's effects in registry order, then the robot candidates.
const std::vector<CandidateType>& candidate_types();
/// nullptr when unknown.
const CandidateType* find_candidate(const std::string& name);

/// A fold cannot test a candidate when the candidate's standard error fitted without the fold
/// is more than this many times its standard error fitted on every run: the fold then holds
/// more than 1 - 1/3^2 = 8/9 of the information about it (OptiOdom's scale and reference offset
/// are pinned by the straight Ivanjko runs alone), and a prediction from the rest extrapolates.
inline constexpr double kMaxFoldStderrRatio = 3.0;

/// A fold can only test a candidate that changes its prediction: its in-sample gain on the
/// fold's runs must reach this many log-likelihood units (a likelihood ratio of e^2 = 7.4,
/// weak evidence on the scale of [Kass95]); a fold the candidate leaves alone has nothing to
/// predict, and its gain (about 0) is not counted.
inline constexpr double kMinFoldSignal = 2.0;

/// A candidate predicts a fold worse when its held-out gain there is below minus this (the
/// same e^2 evidence as kMinFoldSignal, against it): an effect that helps some kinds of path
/// and hurts another is a compromise between them, not their cause, and it is a mimic even
/// when its gains elsewhere outweigh the loss. On the quasi-likelihood's scale: a systematic
/// candidate whose model leaves the experiments' means dispersed phi times the predicted
/// (Candidate::mean_dispersion) may lose phi times this.
inline constexpr double kMaxFoldLoss = 2.0;

/// ... and only when the loss is significant against the sampling spread of the fold's held-out
/// gain, one-sided at this family-wise level over the folds (fold_loss_bound): the gain is a sum
/// over the fold's runs, and a loss that the scatter of their gains explains is noise, not a
/// worse prediction (a true spread between groups, fitted on every run, lost 3.9 on 14 spins,
/// 1.4 times the spread of their runs' gains). The studentised sum is Vuong's statistic
/// [Vuong89], as a one-sided test of "the candidate predicts the fold no worse than the base".
inline constexpr double kFoldLossAlpha = 0.05;

/// A fold that holds nearly all the information about a candidate (stderr_ratio r > 3) is not
/// counted, but it can still contradict it: fitted without the fold, the candidate's k
/// parameters are off by about r of the fold's own standard errors, which costs the fold about
/// r^2 chi^2_k / 2 in log-likelihood; a loss beyond kMaxFoldLoss + r^2 q / 2, q the chi^2_k
/// quantile at 1 - kContradictionAlpha, is more than that uncertainty explains.
inline constexpr double kContradictionAlpha = 0.01;
/// ... but only when the fold's training runs determine the candidate at all: its standard error
/// fitted without the fold at most this many times the in-sample one (they hold at least 1% of
/// the information). Beyond, the fold's fit is free to wander (a turn-dependent wheelbase's arc
/// part fitted without any arc), and its value says nothing about what the other runs want.
inline constexpr double kMaxContradictionStderrRatio = 10.0;
double contradiction_bound(double stderr_ratio, int dof);

/// Family-wise level of diagnose's decision: the best candidate must have p < alpha/m over the
/// m candidates (Bonferroni). 0.01 keeps false alarms near 1% while finding moderate effects.
inline constexpr double kDiagnoseAlpha = 0.01;

struct ModelSummary {
  double log_likelihood = 0.0;
  double nees_mean = 0.0;  // over all runs
  std::string verdict;     // compare's, at the same alpha
  Calibration calibration;  // how compare calibrated that verdict
};
/// A comparison in brief: its log-likelihood, the NEES mean over all runs and its verdict.
ModelSummary summarise(const Comparison& comparison);

/// True when a new model moves the NEES mean further from 3 than the model before it, by more
/// than the NEES mean's sampling error over `runs` runs allows, 2 sqrt(6/runs) (a right model's
/// per-run NEES is chi^2_3, variance 6): an adoption that makes the predicted spread worse.
bool moves_nees_away(const ModelSummary& before, const ModelSummary& after, std::size_t runs);

struct Candidate {
  std::string effect;  // catalogue name or kWheelNoiseLevel
  std::vector<std::string> parameters;  // the effect's parameter names (k_left, k_right)
  std::vector<double> values;
  std::vector<double> stderrs;  // NaN where the data do not give one
  bool systematic = false;  // moves the mean (fitted on the full likelihood), else on scatter
  /// The gain in the likelihood the candidate is fitted and judged on, against the model with
  /// its own effects refitted: the full one for a systematic candidate, the scatter part for a
  /// random one. Its LRT and delta BIC come from this.
  double delta_log_likelihood = 0.0;
  double delta_full_log_likelihood = 0.0;  // the gain in the full likelihood, for reference
  double delta_bic = 0.0;             // -2 dLL + (free parameters) ln(runs): < 0 favours it
  double p_value = 1.0;  // likelihood ratio, chi^2 (boundary: 1/2 chi^2 mixture)
  /// What the ratio was divided by before p_value: a random candidate's sandwich variance over
  /// its observed information's where the errors are heavy-tailed, else 1 (docs/calibrate.md,
  /// "Significance under heavy tails").
  double tails_scale = 1.0;
  int dof = 0;
  bool significant = false;
  /// The experiments whose likelihood rose most, with the rise: where the effect showed.
  std::vector<std::pair<std::string, double>> evidence;
  std::string note;   // how a parameter was found when the likelihood cannot (bumps' sigma)
  /// How the impulse size of a heavy-tailed effect was set by the data's tails (match_tails),
  /// "" when it was not; a later match replaces it.
  std::string tails_note;
  std::string physics, signature;  // its CandidateType's, for explain
  bool robot = false;              // moves robot parameters: its YAML is the robot line
  SuiteModel model;   // the model with this candidate added

  // ---- The decision. The fast path screens every candidate; a fit it cannot verify is redone
  // on the exact path (refit_exactly) before anything is ranked. The significant candidates are
  // then judged in order, and the first that passes every rule is adopted.
  bool exact = false;  // its fit was redone on the exact path (the fast one was not verified)
  /// A systematic candidate's gain in the mean alone: its predicted means against the base's,
  /// both under the base's covariances (NaN for random candidates and group_variation), and
  /// that gain's likelihood-ratio p-value.
  double delta_mean_log_likelihood = std::numeric_limits<double>::quiet_NaN();
  double mean_p_value = std::numeric_limits<double>::quiet_NaN();
  /// How far the experiments' mean errors scatter, with the candidate in, beyond what the model
  /// predicts once each experiment's covariance is scaled by the scatter of its own runs (the
  /// quasi-likelihood dispersion, at least 1), and the gain's p-value against both (the F test
  /// of the gain under the scaled covariances; the likelihood ratio's when phi is 1). NaN where
  /// mean_p_value is.
  double mean_dispersion = std::numeric_limits<double>::quiet_NaN();
  double mean_p_value_dispersed = std::numeric_limits<double>::quiet_NaN();
  /// The gain in held-out log-likelihood over the base (its part of the likelihood), summed
  /// over the folds that can test it, each fold predicted by the candidate and by the base both
  /// fitted without it; and per fold. NaN / empty when it was not cross-validated.
  double delta_held_out = std::numeric_limits<double>::quiet_NaN();
  struct FoldGain {
    std::string fold;
    double gain = 0.0;
    /// The largest ratio of a parameter's standard error fitted without the fold to its
    /// standard error fitted on every run (infinite where the fold's fit gives none).
    double stderr_ratio = 1.0;
    /// The candidate's in-sample gain on the fold's runs (the part it is judged on).
    double signal = 0.0;
    /// False when the fold cannot test the candidate: it holds nearly all that the runs say
    /// about it (stderr_ratio > kMaxFoldStderrRatio: fitted without it, the candidate is not
    /// determined) or about a parameter of the model (`undetermined`), or the candidate changes
    /// nothing there (|signal| < kMinFoldSignal). Its gain is then not counted.
    bool counted = true;
    /// An undetermined fold's loss beyond what the uncertainty of the candidate fitted without
    /// it explains (contradiction_bound): the estimate from the other folds is not the one this
    /// fold wants, so the candidate is not one cause of both.
    bool contradicts = false;
    /// The sampling standard deviation of `gain` from the scatter of its parts
    /// (spread_of_sum), and their number; NaN when it has fewer than two.
    double spread = std::numeric_limits<double>::quiet_NaN();
    std::size_t parts = 0;
    /// The same ratio over the parameters of the model the candidate joins (the base's, refitted
    /// with it), and the one beyond kMaxFoldStderrRatio ("" when none is): a fold whose training
    /// runs leave the model itself undetermined cannot test the candidate either.
    double model_stderr_ratio = 1.0;
    std::string undetermined;
    /// Where the candidate fitted without the fold cannot predict the fold's runs at all (a
    /// custom expression leaves its range on them), why ("" else): the fold then contradicts
    /// it, with no gain.
    std::string wall;
  };
  std::vector<FoldGain> held_out_by_fold;
  /// "adopted"; "mimic" (significant in-sample, predicts the held-out folds worse in all, one of
  /// them worse by more than kMaxFoldLoss on the quasi-likelihood's scale, or a fold that could
  /// not test it worse than its uncertainty explains); "stopped" (significant, but a guard
  /// stopped it: `rule`); "not significant"; "not judged" (significant, ranked after the
  /// adopted one).
  std::string verdict = "not significant";
  /// The rule that stopped a stopped candidate or named a mimic: "parameter at bound",
  /// "confounded", "covariance, not mean", "held-out likelihood", "across the feature" (a
  /// systematic candidate that does not predict across the base's mean feature), "scatter
  /// shape" (a random candidate that leaves the scatter's feature significant), "NEES",
  /// "nested" (a simpler candidate it contains fits as well), "consistency", "" otherwise.
  std::string rule;
  std::string decision;  // the verdict in plain words
  std::vector<std::string> at_bound;  // parameters its fit left at a bound (FitResult::at_bound)
  /// The largest |correlation| of its own parameters' estimates with a parameter of the
  /// model's effects refitted beside it (1 without a standard error), and that parameter.
  double confounded = 0.0;
  std::string confounded_with;
};

/// The p-value of a likelihood-ratio gain `delta` (in log-likelihood) with `dof` parameters:
/// chi^2, halved on the boundary [Self87].
double lrt_p_value(double delta, int dof, bool on_boundary);

/// The loss beyond which a counted fold is predicted worse: kMaxFoldLoss times the candidate's
/// mean dispersion `phi` (at least 1), and the gain's spread (when it has one) times the
/// one-sided point of Student's t with parts - 1 degrees of freedom at kFoldLossAlpha / tested,
/// `tested` the candidate's counted folds (Bonferroni: a true effect is called a mimic by the
/// noise of its folds' gains at most kFoldLossAlpha of the time).
double fold_loss_bound(const Candidate::FoldGain& gain, double phi, std::size_t tested);

struct Diagnosis {
  double alpha = kDiagnoseAlpha;
  /// The folds the significant candidates were cross-validated on (none: judged in-sample).
  Folds folds;
  std::size_t runs = 0;
  ModelSummary before;
  std::vector<Candidate> candidates;  // best first
  std::optional<std::size_t> best;    // index into candidates, if significant
  ModelSummary after;                 // with the best added (= before when none)
  TestResult kurtosis;                // the shape test that separates bumps from noise level
  bool heavy_tails = false;
  /// True only when the final model (the best candidate's when one is named, else the suite's)
  /// is consistent with the data at alpha, as compare judges it.
  bool explained = false;
  /// What the final model's misfit lines up with, best first (residual_alignment); filled
  /// whenever explained is false.
  std::vector<ResidualAlignment> residuals;
  /// The corrected odometry the final model's systematic effects imply, with the runs'
  /// end-pose error re-integrated before and after (none without such effects).
  std::optional<OdometryCorrection> odometry_correction;
};

/// Runs every candidate (all catalogue effects not in the model, group_variation of the
/// model's systematic parameters and of those that vary between groups when the suite has
/// groups, and wheel_noise_level; or the `only` subset; plus the user's `candidates`).
/// Parameters of effects already in the model are refitted alongside each candidate, and the
/// likelihood gain is measured against that refitted model.
///
/// Each candidate is fitted and judged on the part of the Gaussian likelihood it explains:
/// systematic candidates (Ed, Eb, Es) on the full likelihood; random ones on its scatter part
/// (scatter_log_likelihood), so a variance effect cannot gain by absorbing a mean misfit. The
/// gains are on one scale: the LRT gives each p-value (for random candidates scaled by the
/// kurtosis when the tails are heavy, [Browne84]) and delta BIC ranks them, significant ones
/// first. One signature rule settles the pair a Gaussian likelihood cannot tell apart: bumps and
/// wheel_noise_level both add variance that grows with distance, so heavy tails (Mardia's
/// kurtosis, shape only) put bumps ahead of wheel_noise_level and Gaussian tails the reverse.
///
/// `progress`, when given, is kept up to date for a progress display (the library prints
/// nothing): the number of fits to run and done, and the likelihood evaluations so far.
struct DiagnoseProgress {
  std::atomic<std::int64_t> fits_total{0};
  std::atomic<std::int64_t> fits_done{0};
  std::atomic<std::int64_t> evaluations{0};
  /// Set from outside (Ctrl-C) to stop: diagnose then throws Cancelled between two fits.
  std::atomic<bool> cancel{false};
  /// The round calibrate is in (1, 2, ...; 0 outside calibrate).
  std::atomic<int> round{0};
};

/// What diagnose and calibrate throw when DiagnoseProgress::cancel is set.
struct Cancelled : std::runtime_error {
  Cancelled() : std::runtime_error("cancelled") {}
};

/// How one diagnose round runs and decides.
struct DiagnoseOptions {
  double alpha = kDiagnoseAlpha;
  /// Only these candidates (by their name or their effect's); empty: all.
  std::vector<std::string> only;
  /// The user's own hypotheses (diagnose --candidates), tried from their given values.
  EffectList candidates;
  FitPath path = FitPath::fast;
  /// Judge the significant candidates on the suite's folds (make_folds): a candidate that does
  /// not predict the held-out folds better than the base is a mimic and is not adopted. With
  /// false (or a suite of one experiment) they are judged in-sample only.
  bool cross_validate = true;
  /// How the compares of the model before and after calibrate their verdicts (compare; the
  /// referee's seed and replicates).
  CalibrationOptions calibration;
};
/// `candidates`: the user's own hypotheses (custom effects, or catalogue effects with starting
/// values), tried beside the catalogue from their given values (diagnose --candidates).
/// `path` is how every fit evaluates the likelihood (FitPath): the fast path shares one
/// ResidualCache over the round, so each candidate parameter's sensitivity around the refitted
/// model is propagated once.
Diagnosis diagnose(const Suite& suite, const SuiteModel& model, const DiagnoseOptions& options,
                   DiagnoseProgress* progress = nullptr);
/// The same with `cache` (of `suite`) holding every exact propagation and verdict: the fast
/// path's anchors and difference points around the base model are shared by all candidates and
/// by their fits on the folds, and calibrate's rounds share them with each other (a round's
/// base refit starts where the previous round's winner ended).
Diagnosis diagnose(const Suite& suite, const SuiteModel& model, const DiagnoseOptions& options,
                   DiagnoseProgress* progress, ResidualCache& cache);
/// The same with the options one by one (cross-validated).
/// `calibration` is how the compares of the model before and after calibrate their verdicts
/// (compare; the referee's seed and replicates).
Diagnosis diagnose(const Suite& suite, const SuiteModel& model, double alpha = kDiagnoseAlpha,
                   const std::vector<std::string>& only = {}, DiagnoseProgress* progress = nullptr,
                   const EffectList& candidates = {}, FitPath path = FitPath::fast,
                   const CalibrationOptions& calibration = {});

/// Plain words for a named candidate: the physics, the fitted size, the signature and where it
/// showed, e.g. "unequal wheel diameters (Ed = D_R/D_L): Ed = 1.0041 +/- 0.0002; heading drifts
/// ...; it showed most in line-8m (log-likelihood +812) and line-2m (+61)".
std::string explain(const Candidate& c);

/// The YAML to paste: an effect for model.effects, or the robot line for wheel_noise_level.
std::string candidate_yaml(const Candidate& c, const SuiteModel& model);

/// The closing words of diagnose's report: "explained" only when it is; otherwise that the
/// model is still inconsistent and the features the misfit lines up with (at most three),
/// with their p-values and what kind of effect each points at.
std::string verdict_text(const Diagnosis& d);

}  // namespace odomcov
