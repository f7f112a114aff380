#include "odomcov/measurement/odometry_correction.hpp"

#include <algorithm>
#include <cmath>
#include <map>

#include "closed_form/arc_functions.hpp"
#include "effects/effect.hpp"

namespace odomcov {
namespace {

/// Running sums for CorrectedParameters over pieces.
struct Sums {
  double rotation = 0.0, wheelbase_by_rotation = 0.0;  // sum |dR - dL|, sum B_true |dR - dL|
  double wheelbase = 0.0, pieces = 0.0;                // unweighted fallback
  double encoder_left = 0.0, true_left = 0.0, encoder_right = 0.0, true_right = 0.0;

  void add(const effects::ResolvedPiece& p) {
    const double B = p.wheelbase_true_m;
    const double w = std::abs(p.encoder.right_m - p.encoder.left_m);
    rotation += w;
    wheelbase_by_rotation += B * w;
    wheelbase += B;
    pieces += 1.0;
    // True wheel travel from the true centre travel and heading change.
    encoder_left += std::abs(p.encoder.left_m);
    encoder_right += std::abs(p.encoder.right_m);
    true_left += std::copysign(1.0, p.encoder.left_m) * (p.center_m - 0.5 * B * p.angle_rad);
    true_right += std::copysign(1.0, p.encoder.right_m) * (p.center_m + 0.5 * B * p.angle_rad);
  }
  void add(const Sums& o) {
    rotation += o.rotation, wheelbase_by_rotation += o.wheelbase_by_rotation;
    wheelbase += o.wheelbase, pieces += o.pieces;
    encoder_left += o.encoder_left, true_left += o.true_left;
    encoder_right += o.encoder_right, true_right += o.true_right;
  }
  CorrectedParameters parameters(double nominal_wheelbase_m) const {
    CorrectedParameters c;
    c.wheelbase_m = rotation > 0 ? wheelbase_by_rotation / rotation
                    : pieces > 0 ? wheelbase / pieces
                                 : nominal_wheelbase_m;
    c.scale_left = encoder_left > 0 ? true_left / encoder_left : 1.0;
    c.scale_right = encoder_right > 0 ? true_right / encoder_right : 1.0;
    return c;
  }
};

/// The durations of a run's encoder pieces (encoder_pieces): the logged rows', or those of the
/// sampled path's arcs (one per run of equal samples, as sample_arcs).
std::vector<double> piece_durations(const SuiteExperiment& ex, const SuiteRun& run) {
  if (ex.logged) return run.durations_s;
  std::vector<double> out;
  for (const SampleRun& s : sample_schedule(ex.path)) out.push_back(static_cast<double>(s.count) * s.duration_s);
  return out;
}

/// The pose at the end of the pieces' true motion (each an arc of the true centre travel and
/// heading change).
Vector3 true_end_pose(const effects::ResolvedPath& path) {
  Vector3 pose = Vector3::Zero();
  for (const effects::ResolvedPiece& p : path.pieces) {
    pose = compose(pose, detail::arc_displacement(p.center_m, p.lateral_m, detail::ArcStep(p.angle_rad)));
  }
  return pose;
}

bool same(const CorrectedParameters& a, const CorrectedParameters& b) {
  auto near = [](double x, double y) { return std::abs(x - y) <= 1e-9 * std::max(std::abs(x), std::abs(y)); };
  return near(a.wheelbase_m, b.wheelbase_m) && near(a.scale_left, b.scale_left) &&
         near(a.scale_right, b.scale_right);
}

}  // namespace

std::optional<OdometryCorrection> odometry_correction(const Suite& suite, const SuiteModel& model) {
  const double B = model.robot.wheelbase_m;
  std::vector<std::string> order;
  std::map<std::string, CorrectionByKind> kinds;
  std::map<std::string, Sums> sums;
  bool changes = false;
  for (const SuiteExperiment& ex : suite.experiments) {
    const std::string kind = experiment_kind(ex);
    if (!kinds.count(kind)) order.push_back(kind);
    CorrectionByKind& k = kinds[kind];
    k.kind = kind;
    Eigen::Vector2d cg_before = Eigen::Vector2d::Zero(), cg_after = Eigen::Vector2d::Zero();
    for (const SuiteRun& run : ex.runs) {
      const std::vector<ArcSegment> pieces = encoder_pieces(ex, run);
      const effects::ResolvedPath path =
          effects::resolve(pieces, piece_durations(ex, run), model.robot, model.effects, run.heading0_rad);
      Vector3 nominal = Vector3::Zero();
      for (const ArcSegment& p : pieces) nominal = drive(nominal, p, B);
      for (const effects::ResolvedPiece& p : path.pieces) {
        sums[kind].add(p);
        changes = changes || p.wheelbase_true_m != B || p.center_m != p.encoder.center_m() ||
                  p.angle_rad != p.encoder.heading_change_rad(B);
      }
      const Eigen::Vector2d before = pose_error(run.measured, nominal).head<2>();
      const Eigen::Vector2d after = pose_error(run.measured, true_end_pose(path)).head<2>();
      k.mean_xy_before_m += before.norm();
      k.mean_xy_after_m += after.norm();
      cg_before += before / static_cast<double>(ex.runs.size());
      cg_after += after / static_cast<double>(ex.runs.size());
      ++k.runs;
    }
    k.emax_before_m = std::max(k.emax_before_m, cg_before.norm());
    k.emax_after_m = std::max(k.emax_after_m, cg_after.norm());
  }
  if (!changes) return std::nullopt;
  OdometryCorrection out;
  Sums all;
  for (const std::string& kind : order) all.add(sums[kind]);
  out.parameters = all.parameters(B);
  for (const std::string& kind : order) {
    CorrectionByKind k = kinds[kind];
    k.parameters = sums[kind].parameters(B);
    out.motion_dependent = out.motion_dependent || !same(k.parameters, out.parameters);
    k.mean_xy_before_m /= static_cast<double>(std::max<std::size_t>(1, k.runs));
    k.mean_xy_after_m /= static_cast<double>(std::max<std::size_t>(1, k.runs));
    out.by_kind.push_back(k);
  }
  return out;
}

}  // namespace odomcov
