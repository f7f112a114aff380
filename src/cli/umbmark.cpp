// odomcov umbmark SUITE.yaml --cw NAME[,NAME...] --ccw NAME[,NAME...] [--side L] [--json FILE]
// Borenstein & Feng's UMBmark [Borenstein96] from CW and CCW square runs.
#include <iostream>
#include <optional>
#include <sstream>

#include "commands.hpp"
#include "odomcov/measurement/calibration.hpp"
#include "odomcov/io/suite_io.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

struct UmbmarkOptions {
  std::string suite;
  std::string cw, ccw;
  std::optional<double> side;
  std::string json;
};

std::string cg(const Eigen::Vector2d& v) {
  return "(" + fixed(1000 * v.x(), 2) + ", " + fixed(1000 * v.y(), 2) + ") mm";
}

int run_umbmark(const UmbmarkOptions& opt) {
  if (!opt.json.empty()) check_output_path(opt.json);
  if (opt.side && !(*opt.side > 0)) throw UsageError("--side must be > 0");
  const Suite suite = load_suite(opt.suite);
  const UmbmarkResult r = umbmark(suite, opt.cw, opt.ccw, opt.side);
  std::ostringstream out;
  out << "odomcov umbmark: " << suite.name << ", square side L = " << fixed(r.side_m, 4)
      << " m, b = " << suite.robot.wheelbase_m << " m\n"
      << "  runs: " << r.runs_cw << " CW (" << opt.cw << "), " << r.runs_ccw << " CCW ("
      << opt.ccw << ")\n"
      << "  centres of gravity of the end errors (true - odometry, start frame):\n"
      << "    CW  " << cg(r.cg_cw) << "   CCW " << cg(r.cg_ccw) << "\n"
      << "  alpha = " << sci(r.alpha, 4) << " rad (turning error per 90 deg turn, > 0: under-turns)\n"
      << "  beta  = " << sci(r.beta, 4) << " rad (curvature error per side, > 0: curves left)\n"
      << "  Ed = " << fixed(r.Ed, 6) << " (D_R/D_L), Eb = " << fixed(r.Eb, 6) << "\n"
      << "  corrections: c_L = " << fixed(r.c_left, 6) << ", c_R = " << fixed(r.c_right, 6)
      << ", b_new = " << fixed(r.wheelbase_corrected, 6) << " m\n"
      << "  Emax,sys = " << fixed(1000 * r.emax_before, 2) << " mm before, "
      << fixed(1000 * r.emax_after, 2) << " mm after re-integrating with the corrections\n"
      << "    after: CW " << cg(r.cg_cw_after) << "   CCW " << cg(r.cg_ccw_after) << "\n"
      << "  cross-check, maximum-likelihood fit on the same runs (no small-angle approximation):\n"
      << "    Ed = " << fixed(r.ml_Ed, 6) << " +/- " << sci(r.ml_Ed_stderr, 1)
      << ", Eb = " << fixed(r.ml_Eb, 6) << " +/- " << sci(r.ml_Eb_stderr, 1) << "\n"
      << "    Emax,sys after re-integrating with these instead: " << fixed(1000 * r.ml_emax_after, 2)
      << " mm\n";
  std::cout << out.str();
  if (!opt.json.empty()) {
    auto vec = [](const Eigen::Vector2d& v) { return json::array({v.x(), v.y()}); };
    write_json_atomic(opt.json, {{"alpha", r.alpha},
                                 {"beta", r.beta},
                                 {"Ed", r.Ed},
                                 {"Eb", r.Eb},
                                 {"c_left", r.c_left},
                                 {"c_right", r.c_right},
                                 {"wheelbase_corrected", r.wheelbase_corrected},
                                 {"emax_sys_before", r.emax_before},
                                 {"emax_sys_after", r.emax_after},
                                 {"side", r.side_m},
                                 {"cg_cw", vec(r.cg_cw)},
                                 {"cg_ccw", vec(r.cg_ccw)},
                                 {"cg_cw_after", vec(r.cg_cw_after)},
                                 {"cg_ccw_after", vec(r.cg_ccw_after)},
                                 {"runs_cw", r.runs_cw},
                                 {"runs_ccw", r.runs_ccw},
                                 {"ml_fit", {{"Ed", r.ml_Ed}, {"Eb", r.ml_Eb},
                                             {"stderr", {{"Ed", r.ml_Ed_stderr}, {"Eb", r.ml_Eb_stderr}}},
                                             {"emax_sys_after", r.ml_emax_after}}}});
  }
  return kExitOk;
}

}  // namespace

void setup_umbmark(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<UmbmarkOptions>();
  CLI::App* cmd = app.add_subcommand("umbmark", "Borenstein-Feng UMBmark calibration from squares");
  cmd->add_option("suite", opt->suite, "Measurement suite (YAML)")->required();
  cmd->add_option("--cw", opt->cw, "Clockwise square experiment(s), comma-separated")->required();
  cmd->add_option("--ccw", opt->ccw, "Counter-clockwise square experiment(s), comma-separated")
      ->required();
  cmd->add_option("--side", opt->side, "Square side L [m] (default: the planned paths' line length)");
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->callback([opt, &exit_code] { exit_code = run_umbmark(*opt); });
}

}  // namespace odomcov::cli
