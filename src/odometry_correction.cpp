#include "odomcov/odometry_correction.hpp"

#include <algorithm>
#include <map>

namespace odomcov {

std::optional<OdometryCorrection> odometry_correction(const Suite& suite, const SuiteModel& model) {
  double Ed = 1.0, Eb = 1.0, Es = 1.0;
  bool any = false;
  for (const EffectSpec& e : model.effects) {
    if (e.name == "wheel_diameter_ratio") Ed = e.values[0], any = true;
    if (e.name == "wheelbase_error") Eb = e.values[0], any = true;
    if (e.name == "scale_error") Es = e.values[0], any = true;
  }
  if (!any) return std::nullopt;
  const double B = model.robot.wheelbase_m;
  OdometryCorrection out;
  out.wheelbase_m = Eb * B;
  out.scale_left = Es * 2.0 / (Ed + 1.0);
  out.scale_right = Es * 2.0 * Ed / (Ed + 1.0);

  std::vector<std::string> order;
  std::map<std::string, CorrectionByKind> kinds;
  for (const SuiteExperiment& ex : suite.experiments) {
    const std::string kind = ex.name.substr(0, ex.name.find('-'));
    if (!kinds.count(kind)) order.push_back(kind);
    CorrectionByKind& k = kinds[kind];
    k.kind = kind;
    Eigen::Vector2d cg_before = Eigen::Vector2d::Zero(), cg_after = Eigen::Vector2d::Zero();
    for (const SuiteRun& run : ex.runs) {
      const std::vector<ArcSegment> pieces = encoder_pieces(ex, run);
      Vector3 nominal = Vector3::Zero(), corrected = Vector3::Zero();
      for (const ArcSegment& p : pieces) {
        nominal = drive(nominal, p, B);
        corrected = drive(corrected, {out.scale_left * p.left_m, out.scale_right * p.right_m}, out.wheelbase_m);
      }
      const Eigen::Vector2d before = pose_error(run.measured, nominal).head<2>();
      const Eigen::Vector2d after = pose_error(run.measured, corrected).head<2>();
      k.mean_xy_before_m += before.norm();
      k.mean_xy_after_m += after.norm();
      cg_before += before / static_cast<double>(ex.runs.size());
      cg_after += after / static_cast<double>(ex.runs.size());
      ++k.runs;
    }
    k.emax_before_m = std::max(k.emax_before_m, cg_before.norm());
    k.emax_after_m = std::max(k.emax_after_m, cg_after.norm());
  }
  for (const std::string& kind : order) {
    CorrectionByKind k = kinds[kind];
    k.mean_xy_before_m /= static_cast<double>(std::max<std::size_t>(1, k.runs));
    k.mean_xy_after_m /= static_cast<double>(std::max<std::size_t>(1, k.runs));
    out.by_kind.push_back(k);
  }
  return out;
}

}  // namespace odomcov
