// odomcov import optiodom SESSION_DIR... --out DIR [--wheelbase B] [--diameters DL,DR] [--k K]
//                                         [--xy M] [--theta-deg D] [--name NAME] [--json FILE]
// Converts the OptiOdom recordings into a measurement suite with per-run encoder logs.
#include <filesystem>
#include <iostream>

#include "commands.hpp"
#include "odomcov/optiodom.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

struct ImportOptions {
  std::vector<std::string> sessions;
  std::string out;
  std::optional<double> wheelbase;
  std::vector<double> diameters;
  double k = 1e-3;
  double xy = 0.001;
  double theta_deg = 0.1;
  std::string name = "optiodom";
  std::string json;
};

int run_import(const ImportOptions& opt) {
  namespace fs = std::filesystem;
  check_output_dir(opt.out);
  if (!opt.json.empty()) check_output_path(opt.json);
  if (opt.wheelbase && !(*opt.wheelbase > 0)) throw UsageError("--wheelbase must be > 0");
  if (!opt.diameters.empty() && (opt.diameters.size() != 2 || !(opt.diameters[0] > 0) || !(opt.diameters[1] > 0))) {
    throw UsageError("--diameters needs two positive values DL,DR");
  }
  if (!(opt.k > 0) || opt.xy < 0 || opt.theta_deg < 0) throw UsageError("--k must be > 0, --xy and --theta-deg >= 0");
  OptiOdomOptions o;
  o.sessions = opt.sessions;
  o.wheelbase_m = opt.wheelbase;
  if (!opt.diameters.empty()) o.diameters_m = std::make_pair(opt.diameters[0], opt.diameters[1]);
  o.k = opt.k;
  o.measurement_noise = {opt.xy, opt.theta_deg * kDegToRad};
  o.name = opt.name;
  std::vector<ImportSummary> summary;
  const std::vector<ImportedFile> files = import_optiodom(o, &summary);  // all read first
  StagedDir stage(opt.out);
  const fs::path dir(stage.final_dir());
  for (const ImportedFile& f : files) stage.write(f.path, f.text);
  stage.commit();
  std::cout << "odomcov import optiodom: " << opt.sessions.size() << " sessions -> "
            << (dir / "suite.yaml").string() << "\n"
            << "  experiment                              runs  mean travel  mean turn\n";
  json experiments = json::array();
  for (const ImportSummary& s : summary) {
    char line[160];
    std::snprintf(line, sizeof line, "  %-38s %5zu  %8.3f m  %+8.3f rad\n", s.experiment.c_str(),
                  s.runs, s.mean_travel_m, s.mean_turn_rad);
    std::cout << line;
    experiments.push_back({{"name", s.experiment}, {"runs", s.runs},
                           {"mean_travel", s.mean_travel_m}, {"mean_turn", s.mean_turn_rad}});
  }
  if (!opt.json.empty()) {
    write_json_atomic(opt.json, {{"suite", (dir / "suite.yaml").string()}, {"experiments", experiments}});
  }
  return kExitOk;
}

}  // namespace

void setup_import(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<ImportOptions>();
  CLI::App* cmd = app.add_subcommand("import", "Import recordings as a measurement suite");
  cmd->require_subcommand(1);
  CLI::App* sub = cmd->add_subcommand("optiodom", "The OptiOdom recordings (ticks + OptiTrack)");
  sub->add_option("sessions", opt->sessions, "Session directories (e.g. .../diff/square/230620202042)")
      ->required();
  sub->add_option("--out", opt->out, "Directory for suite.yaml and the logs")->required();
  sub->add_option("--wheelbase", opt->wheelbase, "Nominal wheelbase [m] (default: metadata Li)");
  sub->add_option("--diameters", opt->diameters, "Wheel diameters DL,DR [m] (default: metadata Di)")
      ->delimiter(',');
  sub->add_option("--k", opt->k, "Nominal wheel noise constant for both wheels [m^(1/2)]")
      ->capture_default_str();
  sub->add_option("--xy", opt->xy, "Reference position noise (std-dev) [m]")->capture_default_str();
  sub->add_option("--theta-deg", opt->theta_deg, "Reference heading noise (std-dev) [deg]")
      ->capture_default_str();
  sub->add_option("--name", opt->name, "Suite name")->capture_default_str();
  sub->add_option("--json", opt->json, "Write a summary as JSON to this file");
  sub->callback([opt, &exit_code] { exit_code = run_import(*opt); });
}

}  // namespace odomcov::cli
