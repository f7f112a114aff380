// odomcov import optiodom SESSION_DIR... --out DIR [--wheelbase B] [--diameters DL,DR] [--k K]
//                                         [--xy M] [--theta-deg D] [--name NAME] [--json FILE]
//                                         [--group session|day]
// odomcov import csv LOG.csv|DIR... --out DIR --wheelbase B [--left-scale S] [--right-scale S]
//                    [--k K] [--xy M] [--theta-deg D] [--name NAME] [--json FILE]
// Convert recordings into a measurement suite with per-run encoder logs.
#include <cmath>
#include <filesystem>
#include <iostream>

#include "commands.hpp"
#include "odomcov/io/csv_import.hpp"
#include "odomcov/io/optiodom.hpp"
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
  std::string group = "session";  // or "day"
};

/// Writes an import's files (every file was read and checked before: bad input writes nothing),
/// suite.yaml last, and prints the per-experiment summary.
void write_import(const std::string& kind, const std::string& what, const std::string& out,
                  const std::string& json_file, const std::vector<ImportedFile>& files,
                  const std::vector<ImportSummary>& summary) {
  namespace fs = std::filesystem;
  // All or nothing: every file goes into a staging directory beside `out`, moved into place
  // only when all are written.
  StagedDir stage(out);
  for (const ImportedFile& f : files) stage.write(f.path, f.text);
  stage.commit();
  const fs::path dir(stage.final_dir());
  const bool with_reference = !summary.empty() && summary.front().mean_reference_travel_m >= 0;
  std::cout << "odomcov import " << kind << ": " << what << " -> " << (dir / "suite.yaml").string() << "\n"
            << "  experiment                              runs  mean travel  mean turn"
            << (with_reference ? "  reference travel" : "") << "\n";
  json experiments = json::array();
  for (const ImportSummary& s : summary) {
    char line[200];
    std::snprintf(line, sizeof line, "  %-38s %5zu  %8.3f m  %+8.3f rad", s.experiment.c_str(),
                  s.runs, s.mean_travel_m, s.mean_turn_rad);
    std::cout << line;
    if (with_reference) {
      std::snprintf(line, sizeof line, "  %10.3f m", s.mean_reference_travel_m);
      std::cout << line;
    }
    std::cout << "\n";
    json e = {{"name", s.experiment}, {"runs", s.runs}, {"mean_travel", s.mean_travel_m},
              {"mean_turn", s.mean_turn_rad}};
    if (with_reference) e["mean_reference_travel"] = s.mean_reference_travel_m;
    experiments.push_back(e);
  }
  if (!json_file.empty()) {
    write_json_atomic(json_file, {{"suite", (dir / "suite.yaml").string()}, {"experiments", experiments}});
  }
}

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
  o.group = opt.group == "day" ? OptiOdomGroup::day : OptiOdomGroup::session;
  std::vector<ImportSummary> summary;
  const std::vector<ImportedFile> files = import_optiodom(o, &summary);  // all read first
  write_import("optiodom", std::to_string(opt.sessions.size()) + " sessions", opt.out, opt.json, files,
               summary);
  return kExitOk;
}

struct CsvOptions {
  std::vector<std::string> inputs;
  std::string out;
  double wheelbase = 0;
  double left_scale = 1, right_scale = 1;
  double k = 1e-3;
  double xy = 0.001;
  double theta_deg = 0.1;
  std::string name = "csv";
  std::string json;
};

int run_import_csv(const CsvOptions& opt) {
  check_output_dir(opt.out);
  if (!opt.json.empty()) check_output_path(opt.json);
  if (!(opt.wheelbase > 0)) throw UsageError("--wheelbase must be > 0");
  if (!(opt.left_scale != 0 && std::isfinite(opt.left_scale)) ||
      !(opt.right_scale != 0 && std::isfinite(opt.right_scale))) {
    throw UsageError("--left-scale and --right-scale must be finite and not 0");
  }
  if (!(opt.k > 0) || opt.xy < 0 || opt.theta_deg < 0) throw UsageError("--k must be > 0, --xy and --theta-deg >= 0");
  CsvImportOptions o;
  o.inputs = opt.inputs;
  o.wheelbase_m = opt.wheelbase;
  o.left_scale = opt.left_scale;
  o.right_scale = opt.right_scale;
  o.k = opt.k;
  o.measurement_noise = {opt.xy, opt.theta_deg * kDegToRad};
  o.name = opt.name;
  std::vector<ImportSummary> summary;
  const std::vector<ImportedFile> files = import_csv_logs(o, &summary);  // all checked first
  write_import("csv", std::to_string(files.size() - 1) + " runs", opt.out, opt.json, files, summary);
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
  sub->add_option("--group", opt->group,
                  "Each experiment's group: its session (the session directory) or the recording "
                  "day (YYYY-MM-DD, a start before 06:00 counting to the evening before)")
      ->check(CLI::IsMember({"session", "day"}))
      ->capture_default_str();
  sub->callback([opt, &exit_code] { exit_code = run_import(*opt); });

  auto copt = std::make_shared<CsvOptions>();
  CLI::App* csv = cmd->add_subcommand(
      "csv", "Your own robot: one CSV per run (t,left,right,x,y,theta), folders are experiments");
  csv->add_option("logs", copt->inputs,
                  "Log files or folders of logs; the runs of one folder form one experiment named "
                  "after it")
      ->required();
  csv->add_option("--out", copt->out, "Directory for suite.yaml and the converted logs")->required();
  csv->add_option("--wheelbase", copt->wheelbase, "Nominal wheelbase B [m]")->required();
  csv->add_option("--left-scale", copt->left_scale,
                  "Metres per unit of the left column (e.g. 0.001 for mm, 2 pi r / ticks per turn)")
      ->capture_default_str();
  csv->add_option("--right-scale", copt->right_scale, "Metres per unit of the right column")
      ->capture_default_str();
  csv->add_option("--k", copt->k, "Nominal wheel noise constant for both wheels [m^(1/2)]")
      ->capture_default_str();
  csv->add_option("--xy", copt->xy, "Reference position noise (std-dev) [m]")->capture_default_str();
  csv->add_option("--theta-deg", copt->theta_deg, "Reference heading noise (std-dev) [deg]")
      ->capture_default_str();
  csv->add_option("--name", copt->name, "Suite name")->capture_default_str();
  csv->add_option("--json", copt->json, "Write a summary as JSON to this file");
  csv->callback([copt, &exit_code] { exit_code = run_import_csv(*copt); });
}

}  // namespace odomcov::cli
