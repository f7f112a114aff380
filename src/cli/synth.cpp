// odomcov synth WORLD.yaml --out DIR [--threads T] [--json FILE]
// Drives a simulated world's experiments and writes the measurement suite a lab would have.
#include <filesystem>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "odomcov/engine/statistics.hpp"
#include "odomcov/io/world.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

struct SynthOptions {
  std::string world;
  std::string out;
  int threads = 0;
  std::string json;
};

int run_synth(const SynthOptions& opt) {
  namespace fs = std::filesystem;
  check_threads(opt.threads);
  if (!opt.json.empty()) check_output_path(opt.json);
  const WorldFile world = load_world(opt.world);
  StagedDir stage(opt.out);  // nothing appears in --out unless every file is written
  const fs::path dir(stage.final_dir());
  std::ostringstream report;
  report << "odomcov synth: " << world.name << " -> " << (dir / "suite.yaml").string() << "\n"
         << "  experiment                 runs   mean measured end pose (x, y, theta)\n";
  json experiments = json::array();
  for (std::size_t i = 0; i < world.experiments.size(); ++i) {
    const WorldExperiment& ex = world.experiments[i];
    const std::vector<Vector3> measured = synthesize(world, i, opt.threads);
    stage.write(ex.name + ".csv", measurements_csv(measured, start_headings(world, i)));
    const SampleMoments m = moments(measured);
    char line[160];
    std::snprintf(line, sizeof line, "  %-26s %4lld   (%.4f, %.4f, %.4f)\n", ex.name.c_str(),
                  static_cast<long long>(ex.runs), m.mean.x(), m.mean.y(), m.mean.z());
    report << line;
    experiments.push_back({{"name", ex.name}, {"runs", ex.runs}, {"file", ex.name + ".csv"},
                           {"measured", moments_json(m.mean, m.cov)}});
  }
  stage.write("suite.yaml", suite_yaml(world));
  stage.commit();
  std::cout << report.str();
  if (!opt.json.empty()) {
    write_json_atomic(opt.json, {{"world", world.file},
                                 {"suite", (dir / "suite.yaml").string()},
                                 {"experiments", experiments}});
  }
  return kExitOk;
}

}  // namespace

void setup_synth(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<SynthOptions>();
  CLI::App* cmd = app.add_subcommand(
      "synth", "Simulate a world with hidden effects and write its measurement suite");
  cmd->add_option("world", opt->world, "World file (YAML)")->required();
  cmd->add_option("--out", opt->out, "Directory for suite.yaml and the CSVs")->required();
  cmd->add_option("--threads", opt->threads, "Worker threads; 0 = all cores")
      ->capture_default_str();
  cmd->add_option("--json", opt->json, "Write a summary as JSON to this file");
  cmd->callback([opt, &exit_code] { exit_code = run_synth(*opt); });
}

}  // namespace odomcov::cli
