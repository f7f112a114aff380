// The odometry's own error, UMBmark-style ([Borenstein96]; [Chong97] eqs. 11-12): the corrected
// odometry parameters a model's systematic effects imply, and the end-pose error of the runs
// re-integrated with them, before and after.
//
// Every systematic effect takes part, catalogue or custom, through the same hooks the model
// uses (each piece's true travel and wheelbase for its motion), so an effect whose factors
// depend on the motion (turn_dependent_wheelbase, a custom speed scale) is corrected as the
// model has it. Its factors are then no single set of numbers: each kind of experiment gets the
// effective values over its own runs' motion, and `motion_dependent` says they differ.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "odomcov/measurement/suite.hpp"

namespace odomcov {

/// Effective corrected odometry parameters over some motion: the true wheelbase weighted by the
/// rotation the encoders saw (|dR - dL| per piece; unweighted where nothing turned), and each
/// wheel's true travel per encoder metre (sum of true travel over sum of encoder travel).
struct CorrectedParameters {
  double wheelbase_m = 0.0;
  double scale_left = 1.0;  // multiply the left wheel's diameter by it
  double scale_right = 1.0;
};

struct CorrectionByKind {
  std::string kind;  // the experiments' kind (SuiteExperiment::kind)
  std::size_t runs = 0;
  CorrectedParameters parameters;  // effective over this kind's runs
  double mean_xy_before_m = 0.0, mean_xy_after_m = 0.0;  // mean |x-y error| over the runs
  /// Emax,sys-like: the largest |centre of gravity of the x-y errors| over the kind's experiments.
  double emax_before_m = 0.0, emax_after_m = 0.0;
};

struct OdometryCorrection {
  /// Effective over all runs. With constant factors: wheelbase Eb B, scales Es 2/(Ed + 1) and
  /// Es 2 Ed/(Ed + 1) ([Chong97] eq. 11 times Es).
  CorrectedParameters parameters;
  /// True when the kinds' effective parameters differ (relative 1e-9): the correction depends
  /// on the motion, and one set of numbers does not describe it.
  bool motion_dependent = false;
  std::vector<CorrectionByKind> by_kind;
};

/// nullopt when no effect of the model changes the odometry (every piece's true travel equals
/// its encoder travel at the nominal wheelbase). Errors are measured - odometry in the start
/// frame; "before" integrates the encoder travel with the nominal robot, "after" integrates each
/// piece's true travel and wheelbase as the model's systematic effects give them.
std::optional<OdometryCorrection> odometry_correction(const Suite& suite, const SuiteModel& model);

}  // namespace odomcov
