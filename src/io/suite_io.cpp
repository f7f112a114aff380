// Loading a measurement suite (docs/formats.md, "Measurement suite"): the YAML, the
// measurement CSVs and the encoder logs it names. Part of odomcov::io.
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <set>

#include "io/config_yaml.hpp"
#include "io/csv.hpp"
#include "io/wheel_log.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_io.hpp"
#include "io/yaml_util.hpp"

namespace odomcov {
namespace {

using yaml::Where;


/// The optional `heading0` cell of a row (column `c`): the run's start heading in the
/// reference's frame [rad], a finite number at most kMaxTurn_rad in magnitude (limits.hpp).
double heading0_of(const std::string& file, const csv::Row& row, std::size_t c) {
  const double h = row.number(c);
  if (const std::string e = limits::check_angle(h); !e.empty()) csv::fail(file, row.line, "heading0", e);
  return h;
}

std::vector<SuiteRun> load_measurements(const std::string& csv_file) {
  const csv::Table table = csv::read(csv_file, {"run", "x", "y", "theta"}, "heading0");
  const bool has_heading0 = table.meta->columns.size() == 5;
  std::vector<SuiteRun> runs;
  std::set<std::string> ids;
  for (const csv::Row& row : table.rows) {
    SuiteRun run;
    run.id = row.text(0);
    if (run.id.empty()) csv::fail(csv_file, row.line, "run", "empty run id");
    if (!ids.insert(run.id).second) {
      csv::fail(csv_file, row.line, "run", "duplicate run id " + quote(run.id));
    }
    run.measured = {row.number(1), row.number(2), row.number(3)};
    wheel_log::check_pose(csv_file, row, 1);
    if (has_heading0) {
      run.heading0_rad = heading0_of(csv_file, row, 4);
      run.heading0_given = true;
    }
    runs.push_back(std::move(run));
  }
  return runs;
}

/// A log's optional `heading0` column: the run's start heading, on the first row only (it is
/// one value per run); empty there means unknown (0).
void read_log_heading0(const std::string& log_file, const csv::Table& table, SuiteRun& run) {
  if (table.meta->columns.size() != 7) return;
  for (std::size_t i = 1; i < table.rows.size(); ++i) {
    if (!table.rows[i].empty(6)) {
      csv::fail(log_file, table.rows[i].line, "heading0",
                "the run's start heading goes on the first row only (one value per run)");
    }
  }
  if (table.rows[0].empty(6)) return;
  run.heading0_rad = heading0_of(log_file, table.rows[0], 6);
  run.heading0_given = true;
}

SuiteRun load_log(const std::string& log_file) {
  const csv::Table table = csv::read(log_file, {"t", "left", "right", "x", "y", "theta"}, "heading0");
  SuiteRun run;
  run.id = std::filesystem::path(log_file).stem().string();
  read_log_heading0(log_file, table, run);
  const std::vector<wheel_log::Row> rows = wheel_log::read(log_file, table, wheel_log::Origin::zero);
  int reference_line = 0;
  std::size_t reference_pieces = 0;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const wheel_log::Row& row = rows[i];
    if (!row.wheels) csv::fail(log_file, row.line, "left,right", "a suite's log gives both wheels on every row");
    if (i > 0) {
      run.pieces.push_back({row.left_m - rows[i - 1].left_m, row.right_m - rows[i - 1].right_m});
      run.durations_s.push_back(row.t - rows[i - 1].t);
    }
    if (row.reference) {
      run.measured = row.pose;
      reference_line = row.line;
      reference_pieces = run.pieces.size();
    }
  }
  if (reference_line == 0) {
    csv::fail(log_file, table.rows.back().line, "x,y,theta", "the log has no reference pose");
  }
  run.pieces.resize(reference_pieces);  // the model covers the path up to the last reference
  run.durations_s.resize(reference_pieces);
  return run;
}

/// A logged experiment's runs: its `logs` (a list of one log or more, relative to the suite's
/// folder `dir`), each within the loader's limits at the suite's wheelbase [m], none twice.
std::vector<SuiteRun> load_logged_runs(const Where& lw, const YAML::Node& logs,
                                       const std::filesystem::path& dir, double wheelbase_m) {
  yaml::require_sequence(lw, logs);
  if (logs.size() == 0) yaml::fail(lw, logs, "need at least one log");
  std::vector<SuiteRun> runs;
  std::set<std::string> ids;
  for (std::size_t j = 0; j < logs.size(); ++j) {
    const std::string log = (dir / yaml::to_string(lw.index(j), logs[j])).string();
    SuiteRun run = load_log(log);
    if (const std::string e = limits::check_pieces(run.pieces, wheelbase_m); !e.empty()) {
      throw InputError(log, 0, "", e + " (at the suite's wheelbase)");
    }
    if (!ids.insert(run.id).second) yaml::fail(lw.index(j), logs[j], "duplicate log");
    runs.push_back(std::move(run));
  }
  return runs;
}

/// One experiment of the suite (`experiments[i]` at `xw`): a unique name, an optional
/// non-empty group, and either a path with its measurement CSV or logged runs.
SuiteExperiment parse_experiment(const Where& xw, const YAML::Node& node, const std::string& file,
                                 const std::filesystem::path& dir, double wheelbase_m,
                                 std::set<std::string>& names) {
  yaml::require_map(xw, node, {"name", "path", "measurements", "logs", "group", "kind"});
  SuiteExperiment ex;
  ex.name = yaml::to_string(xw.child("name"), yaml::require(xw, node, "name"));
  if (!names.insert(ex.name).second) yaml::fail(xw.child("name"), node["name"], "duplicate experiment name");
  ex.group = yaml::optional_text(xw, node, "group");
  ex.kind = yaml::optional_text(xw, node, "kind", default_kind(ex.name));
  const bool has_measurements = node["measurements"].IsDefined();
  const bool has_logs = node["logs"].IsDefined();
  if (has_measurements == has_logs) {
    yaml::fail(xw, node, "give either 'path' with 'measurements', or 'logs'");
  }
  if (has_measurements) {
    ex.path = parse_path(yaml::require(xw, node, "path"), file, xw.child("path").key, wheelbase_m);
    const std::string csv_file =
        (dir / yaml::to_string(xw.child("measurements"), node["measurements"])).string();
    ex.runs = load_measurements(csv_file);
    return ex;
  }
  if (node["path"]) yaml::fail(xw.child("path"), node["path"], "logged runs carry their own path");
  ex.logged = true;
  ex.runs = load_logged_runs(xw.child("logs"), node["logs"], dir, wheelbase_m);
  return ex;
}

/// The largest value of each domain feature that is a number anyone measured: speeds and
/// lengths as kMaxLength_m (per second), spin fractions are fractions, and durations up to
/// 1e9 s (30 years).
constexpr double kMaxDomainDuration_s = 1e9;

/// One `[lo, hi]` range of a domain: two finite numbers, 0 <= lo <= hi <= `max`.
Domain::Range parse_range(const Where& w, const YAML::Node& node, double max) {
  yaml::require_sequence(w, node);
  if (node.size() != 2) yaml::fail(w, node, "expected [lo, hi]");
  const Domain::Range r{yaml::to_number(w.index(0), node[0]), yaml::to_number(w.index(1), node[1])};
  if (!(r.lo >= 0 && r.hi <= max)) yaml::fail(w, node, "must lie in [0, " + format_number(max) + "]");
  if (!(r.lo <= r.hi)) yaml::fail(w, node, "lo must not exceed hi");
  return r;
}

/// `model: domain:` (docs/formats.md): the training ranges calibrate records, every key given.
Domain parse_domain(const Where& w, const YAML::Node& node) {
  yaml::require_map(w, node, {"speed", "spin_fraction", "length", "duration"});
  Domain d;
  d.speed_mps = parse_range(w.child("speed"), yaml::require(w, node, "speed"), kMaxLength_m);
  d.spin_fraction = parse_range(w.child("spin_fraction"), yaml::require(w, node, "spin_fraction"), 1.0);
  d.length_m = parse_range(w.child("length"), yaml::require(w, node, "length"), kMaxLength_m);
  d.duration_s = parse_range(w.child("duration"), yaml::require(w, node, "duration"), kMaxDomainDuration_s);
  return d;
}

}  // namespace

MeasurementNoise parse_measurement_noise(const YAML::Node& node, const std::string& file,
                                         const std::string& key) {
  const Where where{file, key};
  yaml::require_map(where, node, {"xy", "theta_deg"});
  MeasurementNoise m;
  m.xy_m = yaml::optional_number(where, node, "xy").value_or(0.0);
  m.theta_rad = yaml::optional_number(where, node, "theta_deg").value_or(0.0) * kDegToRad;
  if (!(m.xy_m >= 0 && m.xy_m <= kMaxLength_m)) {
    yaml::fail(where.child("xy"), node["xy"], "must be in [0, " + format_number(kMaxLength_m) + "] m");
  }
  if (!(m.theta_rad >= 0 && m.theta_rad <= kMaxMeasurementNoiseDeg * kDegToRad)) {
    yaml::fail(where.child("theta_deg"), node["theta_deg"],
               "must be in [0, " + format_number(kMaxMeasurementNoiseDeg) + "] deg");
  }
  return m;
}

Suite load_suite_unguarded(const std::string& file);

Suite load_suite(const std::string& file) {
  return yaml::guarded(file, [&] { return load_suite_unguarded(file); });
}

Suite load_suite_unguarded(const std::string& file) {
  const YAML::Node root = yaml::load_file(file);
  const Where where{file, ""};
  yaml::require_map(where, root,
                    {"name", "robot", "measurement_noise", "model", "experiments"});
  Suite suite;
  suite.file = file;
  suite.name = root["name"] ? yaml::to_string(where.child("name"), root["name"])
                            : std::filesystem::path(file).stem().string();
  suite.robot = parse_robot(yaml::require(where, root, "robot"), file, "robot");
  if (const YAML::Node noise = root["measurement_noise"]) {
    suite.measurement_noise = parse_measurement_noise(noise, file, "measurement_noise");
  }
  if (const YAML::Node model = root["model"]) {
    yaml::require_map(where.child("model"), model, {"effects", "domain"});
    if (model["effects"]) suite.model_effects = parse_effects(model["effects"], file, "model.effects");
    if (model["domain"]) suite.model_domain = parse_domain(where.child("model").child("domain"), model["domain"]);
  }
  const Where ew = where.child("experiments");
  const YAML::Node list = yaml::require(where, root, "experiments");
  yaml::require_sequence(ew, list);
  if (list.size() == 0) yaml::fail(ew, list, "need at least one experiment");
  const std::filesystem::path dir = std::filesystem::path(file).parent_path();
  std::set<std::string> names;
  for (std::size_t i = 0; i < list.size(); ++i) {
    suite.experiments.push_back(parse_experiment(ew.index(i), list[i], file, dir, suite.robot.wheelbase_m, names));
  }
  return suite;
}


}  // namespace odomcov
