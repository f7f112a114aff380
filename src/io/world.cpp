#include "odomcov/io/world.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <set>
#include <stdexcept>

#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/engine/simulator.hpp"
#include "odomcov/io/suite_writer.hpp"
#include "odomcov/io/config_io.hpp"
#include "base/random.hpp"
#include "io/config_yaml.hpp"
#include "io/yaml_util.hpp"

namespace odomcov {
namespace {

using yaml::Where;

/// The longest experiment name: synth writes `<name>.csv`, and file systems allow 255 bytes.
constexpr std::size_t kMaxExperimentName = 200;

/// A name that can name a file: 1 to kMaxExperimentName of A-Z, a-z, 0-9, '_', '.' and '-'.
/// (Checked by hand: std::regex's backtracking matcher recursed once per character and
/// overflowed the stack on a 300 000-character name.)
bool safe_file_name(const std::string& name) {
  return !name.empty() && name.size() <= kMaxExperimentName && std::all_of(name.begin(), name.end(), [](unsigned char c) {
    return std::isalnum(c) != 0 || c == '_' || c == '.' || c == '-';
  });
}

/// An experiment's `heading0:` [rad]: a number, or {uniform: [lo, hi]} with lo < hi, each at most
/// kMaxTurn_rad in magnitude (limits.hpp).
StartHeading parse_start_heading(const Where& where, const YAML::Node& node) {
  StartHeading h;
  h.given = true;
  if (node.IsScalar()) {
    h.lo = h.hi = yaml::to_number(where, node);
    if (const std::string e = limits::check_angle(h.lo); !e.empty()) yaml::fail(where, node, e);
    return h;
  }
  yaml::require_map(where, node, {"uniform"});
  const Where uw = where.child("uniform");
  const YAML::Node range = yaml::require(where, node, "uniform");
  if (!range.IsSequence() || range.size() != 2) yaml::fail(uw, range, "expected [lo, hi] in rad");
  h.lo = yaml::to_number(uw.index(0), range[0]);
  h.hi = yaml::to_number(uw.index(1), range[1]);
  for (std::size_t i = 0; i < 2; ++i) {
    if (const std::string e = limits::check_angle(i ? h.hi : h.lo); !e.empty()) yaml::fail(uw.index(i), range[i], e);
  }
  if (!(h.lo < h.hi)) yaml::fail(uw, range, "needs lo < hi");
  return h;
}

}  // namespace

WorldFile load_world_unguarded(const std::string& file);

WorldFile load_world(const std::string& file) {
  return yaml::guarded(file, [&] { return load_world_unguarded(file); });
}

WorldFile load_world_unguarded(const std::string& file) {
  const YAML::Node root = yaml::load_file(file);
  const Where where{file, ""};
  yaml::require_map(where, root,
                    {"name", "robot", "world", "measurement_noise", "seed", "experiments"});
  WorldFile w;
  w.file = file;
  w.name = root["name"] ? yaml::to_string(where.child("name"), root["name"])
                        : std::filesystem::path(file).stem().string();
  w.robot = parse_robot(yaml::require(where, root, "robot"), file, "robot");
  w.world.noise = w.robot.noise;
  if (root["world"]) w.world = parse_world(root["world"], file, "world", w.robot.noise);
  if (const YAML::Node noise = root["measurement_noise"]) {
    w.measurement_noise = parse_measurement_noise(noise, file, "measurement_noise");
  }
  if (root["seed"]) w.seed = yaml::to_unsigned(where.child("seed"), root["seed"]);
  const Where ew = where.child("experiments");
  const YAML::Node list = yaml::require(where, root, "experiments");
  yaml::require_sequence(ew, list);
  if (list.size() == 0) yaml::fail(ew, list, "need at least one experiment");
  std::set<std::string> names;
  std::int64_t total_runs = 0;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const Where xw = ew.index(i);
    const YAML::Node node = list[i];
    yaml::require_map(xw, node, {"name", "runs", "path", "group", "kind", "heading0"});
    WorldExperiment ex;
    ex.line = yaml::line_of(node);
    ex.name = yaml::to_string(xw.child("name"), yaml::require(xw, node, "name"));
    if (!safe_file_name(ex.name)) {
      yaml::fail(xw.child("name"), node["name"], "use 1 to " + std::to_string(kMaxExperimentName) + " letters, digits, '_', '.' or '-' (it names a file)");
    }
    if (!names.insert(ex.name).second) yaml::fail(xw.child("name"), node["name"], "duplicate name");
    ex.group = yaml::optional_text(xw, node, "group");
    ex.kind = yaml::optional_text(xw, node, "kind");
    ex.runs = yaml::to_integer(xw.child("runs"), yaml::require(xw, node, "runs"), 2, kMaxWorldRuns);
    total_runs += ex.runs;
    if (total_runs > kMaxWorldRuns) {
      yaml::fail(xw.child("runs"), node["runs"],
                 "the experiments up to this one have " + std::to_string(total_runs) +
                     " runs in all, more than the limit of " + std::to_string(kMaxWorldRuns));
    }
    ex.path = parse_path(yaml::require(xw, node, "path"), file, xw.child("path").key,
                         w.robot.wheelbase_m);
    check_simulation_size(file, yaml::line_of(node["runs"]), xw.child("runs").key, ex.runs,
                          sample_count(ex.path));
    ex.path_yaml = YAML::Dump(node["path"]);
    if (node["heading0"]) ex.heading0 = parse_start_heading(xw.child("heading0"), node["heading0"]);
    w.experiments.push_back(std::move(ex));
  }
  return w;
}

std::vector<double> start_headings(const WorldFile& w, std::size_t experiment) {
  const WorldExperiment& ex = w.experiments.at(experiment);
  if (!ex.heading0.given) return {};
  const auto key = random::key_from_seed(random::derive_seed(w.seed, experiment));
  std::vector<double> out;
  for (std::int64_t r = 0; r < ex.runs; ++r) {
    const double u = ex.heading0.lo == ex.heading0.hi
                         ? 0.0
                         : random::uniform_at(key, static_cast<std::uint64_t>(r), 0, random::kTagStartHeading);
    out.push_back(ex.heading0.lo + (ex.heading0.hi - ex.heading0.lo) * u);
  }
  return out;
}

namespace {

/// The simulated errors of an experiment's runs: one batch when every run starts alike for
/// the effects, else run by run from each run's own start heading (Simulator::reference_error
/// gives run r's numbers exactly as the batch would).
std::vector<Vector3> simulated_errors(const WorldFile& w, const WorldExperiment& ex, const EffectList& effects,
                                      const std::vector<double>& heading0, std::uint64_t seed, int threads,
                                      Vector3& odometry) {
  const Robot robot{w.robot.wheelbase_m, w.world.noise};
  const bool per_run = !heading0.empty() && ex.heading0.lo != ex.heading0.hi && effect_needs(effects).start_heading;
  const Simulator batch(robot, ex.path, effects, heading0.empty() ? 0.0 : heading0.front());
  odometry = batch.odometry_end_pose();
  if (!per_run) return batch.errors(seed, 0, ex.runs, threads);
  std::vector<Vector3> errors;
  for (std::int64_t r = 0; r < ex.runs; ++r) {
    errors.push_back(Simulator(robot, ex.path, effects, heading0[static_cast<std::size_t>(r)]).reference_error(seed, r));
  }
  return errors;
}

}  // namespace

std::vector<Vector3> synthesize(const WorldFile& w, std::size_t experiment, int threads) {
  const WorldExperiment& ex = w.experiments.at(experiment);
  const std::uint64_t seed = random::derive_seed(w.seed, experiment);
  SuiteExperiment as_suite;
  as_suite.name = ex.name;
  as_suite.group = ex.group;
  const EffectList effects = group_effects(w.world.effects, w.seed, group_key(as_suite));
  Vector3 odometry;
  const std::vector<Vector3> errors =
      simulated_errors(w, ex, effects, start_headings(w, experiment), seed, threads, odometry);
  const auto key = random::key_from_seed(seed);
  const Vector3 sigma(w.measurement_noise.xy_m, w.measurement_noise.xy_m,
                      w.measurement_noise.theta_rad);
  std::vector<Vector3> measured;
  for (std::size_t r = 0; r < errors.size(); ++r) {
    Vector3 pose = odometry + errors[r];
    for (std::uint32_t c = 0; c < 3; ++c) {
      if (sigma(c) > 0) pose(c) += sigma(c) * random::normal_at(key, r, c, random::kTagMeasurement);
    }
    pose.z() = wrap_angle(pose.z());
    for (int c = 0; c < 2; ++c) {  // theta is wrapped
      if (const std::string e = limits::check_length(pose(c)); !e.empty()) {
        throw InputError(w.file, ex.line, "experiments[" + std::to_string(experiment) + "]",
                         "run " + std::to_string(r + 1) + " ends with " + (c == 0 ? "x " : "y ") + e +
                             " (the suite would not load): the world's effects are far too large");
      }
    }
    measured.push_back(pose);
  }
  return measured;
}

SuiteDocument world_suite(const WorldFile& w) {
  SuiteDocument doc;
  doc.comments = {"Measurement suite written by `odomcov synth` from " +
                  std::filesystem::path(w.file).filename().string()};
  doc.name = w.name;
  doc.robot = w.robot;
  doc.measurement_noise = w.measurement_noise;
  for (const WorldExperiment& ex : w.experiments) {
    doc.experiments.push_back({ex.name, ex.path_yaml, ex.name + ".csv", {}, ex.group, ex.kind});
  }
  return doc;
}

std::string suite_yaml(const WorldFile& w) { return suite_yaml(world_suite(w)); }

std::string measurements_csv(const std::vector<Vector3>& measured, const std::vector<double>& heading0) {
  if (!heading0.empty() && heading0.size() != measured.size()) {
    throw std::invalid_argument("measurements_csv: one heading0 per run");
  }
  std::string text = heading0.empty() ? "run,x,y,theta\n" : "run,x,y,theta,heading0\n";
  for (std::size_t r = 0; r < measured.size(); ++r) {
    text += std::to_string(r + 1) + "," + format_number(measured[r].x(), "%.17g") + "," +
            format_number(measured[r].y(), "%.17g") + "," + format_number(measured[r].z(), "%.17g");
    if (!heading0.empty()) text += "," + format_number(heading0[r], "%.17g");
    text += "\n";
  }
  return text;
}

}  // namespace odomcov
