// The odometry's own error, UMBmark-style ([Borenstein96]; [Chong97] eqs. 11-12): the corrected
// odometry parameters a model's systematic effects imply, and the end-pose error of the runs
// re-integrated with them, before and after.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "odomcov/suite.hpp"

namespace odomcov {

struct CorrectionByKind {
  std::string kind;  // the experiment name's prefix before the first '-'
  std::size_t runs = 0;
  double mean_xy_before_m = 0.0, mean_xy_after_m = 0.0;  // mean |x-y error| over the runs
  /// Emax,sys-like: the largest |centre of gravity of the x-y errors| over the kind's experiments.
  double emax_before_m = 0.0, emax_after_m = 0.0;
};

struct OdometryCorrection {
  double wheelbase_m = 0.0;   // effective wheelbase, Eb B
  double scale_left = 1.0;    // true travel per encoder metre: Es 2/(Ed + 1) (c_L of [Chong97] eq. 11 times Es)
  double scale_right = 1.0;   // Es 2 Ed/(Ed + 1)
  std::vector<CorrectionByKind> by_kind;
};

/// nullopt when the model has none of the systematic factor effects (wheel_diameter_ratio,
/// wheelbase_error, scale_error). Errors are measured - odometry in the start frame; "before"
/// integrates the encoder travel with the nominal robot, "after" with the corrected parameters.
std::optional<OdometryCorrection> odometry_correction(const Suite& suite, const SuiteModel& model);

}  // namespace odomcov
