#include "odomcov/io/csv_import.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "io/csv.hpp"
#include "io/wheel_log.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"

namespace odomcov {
namespace {

namespace fs = std::filesystem;

struct WheelSample {
  double t = 0, left = 0, right = 0;
};
struct ReferenceSample {
  double t = 0;
  Vector3 pose = Vector3::Zero();  // world frame of the reference, theta unwrapped
  int line = 0;
};

struct ConvertedRun {
  std::string log;               // the suite's log text
  double encoder_travel_m = 0;   // sum (|dL| + |dR|)/2
  double reference_travel_m = 0;
  double turn_rad = 0;           // encoder heading change
};

/// Linear interpolation of the wheels at t, with wheels.front().t <= t <= wheels.back().t.
WheelSample wheels_at(const std::vector<WheelSample>& w, double t) {
  auto it = std::lower_bound(w.begin(), w.end(), t,
                             [](const WheelSample& s, double v) { return s.t < v; });
  if (it == w.begin()) return *it;
  if (it == w.end()) return w.back();
  if (it->t == t) return *it;
  const WheelSample& a = *(it - 1);
  const WheelSample& b = *it;
  const double f = (t - a.t) / (b.t - a.t);
  return {t, a.left + f * (b.left - a.left), a.right + f * (b.right - a.right)};
}

/// The reference pose at t: x, y linear in time, theta along the shorter arc (the samples are
/// unwrapped, so linear interpolation of theta is interpolation on the circle).
Vector3 reference_at(const std::vector<ReferenceSample>& r, double t) {
  auto it = std::lower_bound(r.begin(), r.end(), t,
                             [](const ReferenceSample& s, double v) { return s.t < v; });
  if (it == r.begin()) return it->pose;
  if (it == r.end()) return r.back().pose;
  if (it->t == t) return it->pose;
  const ReferenceSample& a = *(it - 1);
  const ReferenceSample& b = *it;
  const double f = (t - a.t) / (b.t - a.t);
  return a.pose + f * (b.pose - a.pose);
}

/// A reference pose moved into the start frame of the run: R(theta0)^T (p - p0), theta - theta0.
Vector3 in_start_frame(const Vector3& pose, const Vector3& start) {
  const double c = std::cos(start.z()), s = std::sin(start.z());
  const double dx = pose.x() - start.x(), dy = pose.y() - start.y();
  return {c * dx + s * dy, -s * dx + c * dy, pose.z() - start.z()};
}

/// Every number the importer writes, at full precision: Unix timestamps at 1 kHz need 13
/// significant digits to stay distinct, and the written suite must always load back.
std::string number(double v) { return format_number(v, "%.17g"); }

/// A log's rows, read and checked, and the wheel readings and reference poses among them.
struct InputLog {
  std::vector<wheel_log::Row> rows;  // theta unwrapped
  std::vector<WheelSample> wheels;     // scaled to metres
  std::vector<ReferenceSample> refs;   // theta unwrapped
  int last_line = 0;                   // of the file's last row
};

/// Reads and checks every row of a log file (columns t,left,right,x,y,theta; wheel_log::read):
/// each row gives the wheels, the reference pose or both; theta is unwrapped.
InputLog read_log(const std::string& file, const CsvImportOptions& o) {
  const csv::Table table = csv::read(file, {"t", "left", "right", "x", "y", "theta"});
  InputLog log;
  for (const wheel_log::Row& row : wheel_log::read(file, table, wheel_log::Origin::first_row, o.left_scale, o.right_scale)) {
    if (!row.wheels && !row.reference) csv::fail(file, row.line, "left,right,x,y,theta", "the row is empty");
    wheel_log::Row in = row;
    if (row.wheels) log.wheels.push_back({in.t, in.left_m, in.right_m});
    if (row.reference) {
      if (!log.refs.empty()) in.pose.z() = log.refs.back().pose.z() + wrap_angle(in.pose.z() - log.refs.back().pose.z());
      log.refs.push_back({in.t, in.pose, row.line});
    }
    log.rows.push_back(in);
  }
  log.last_line = table.rows.back().line;
  return log;
}

/// The run's span [t_start, t_end] [s]: from the first time both the wheels and the reference
/// are known to the last reference pose within the wheels' time span. Bad input when the log
/// has too few wheel readings, no reference, or no overlap.
std::pair<double, double> run_span(const std::string& file, const InputLog& log) {
  if (log.wheels.size() < 2) csv::fail(file, log.last_line, "left,right", "a run needs two wheel readings or more");
  if (log.refs.empty()) csv::fail(file, log.last_line, "x,y,theta", "the log has no reference pose");
  if (log.refs.front().t >= log.wheels.back().t) {
    csv::fail(file, log.refs.front().line, "x,y,theta",
              "the reference starts at or after the last wheel reading; nothing overlaps");
  }
  const double t_start = std::max(log.wheels.front().t, log.refs.front().t);
  double t_end = t_start;
  for (const ReferenceSample& r : log.refs) {
    if (r.t > t_start && r.t <= log.wheels.back().t) t_end = r.t;
  }
  if (!(t_end > t_start)) {
    csv::fail(file, log.last_line, "x,y,theta", "no reference pose after the start of the run");
  }
  return {t_start, t_end};
}

/// The reference's travel from pose a to pose b [m]: the distance, or the heading change as
/// arc length at half the wheelbase `half_b` [m] when that is longer (turns on the spot).
double reference_step(const Vector3& a, const Vector3& b, double half_b) {
  return std::max(std::hypot(b.x() - a.x(), b.y() - a.y()), half_b * std::abs(b.z() - a.z()));
}

/// The suite's log of the run's span: the wheels' travel since the start (interpolated where a
/// row has none), the reference in the start frame; with the encoder and reference travel and
/// the encoder heading change.
ConvertedRun write_run(const InputLog& log, double t_start, double t_end, const CsvImportOptions& o) {
  const WheelSample w0 = wheels_at(log.wheels, t_start);
  const Vector3 start = reference_at(log.refs, t_start);

  ConvertedRun out;
  // The start heading in the reference's own frame (its heading at the run's start, wrapped to
  // (-pi, pi]), which the start frame drops: the log's heading0, on the first row only.
  out.log = "t,left,right,x,y,theta,heading0\n" + number(t_start) + ",0,0,0,0,0," +
            number(wrap_angle(start.z())) + "\n";
  double left_prev = 0, right_prev = 0;
  Vector3 counted = Vector3::Zero();  // last reference pose counted into the travel
  Vector3 last_ref = Vector3::Zero();
  const double half_b = 0.5 * o.wheelbase_m;
  for (const wheel_log::Row& in : log.rows) {
    if (!(in.t > t_start) || in.t > t_end) continue;
    const WheelSample w = in.wheels ? WheelSample{in.t, in.left_m, in.right_m} : wheels_at(log.wheels, in.t);
    const double left = w.left - w0.left, right = w.right - w0.right;
    out.encoder_travel_m += 0.5 * (std::abs(left - left_prev) + std::abs(right - right_prev));
    left_prev = left;
    right_prev = right;
    out.log += number(in.t) + "," + number(left) + "," + number(right);
    if (in.reference) {
      const Vector3 p = in_start_frame(in.pose, start);
      out.log += "," + number(p.x()) + "," + number(p.y()) + "," + number(p.z()) + ",";
      if (reference_step(counted, p, half_b) >= kReferenceStepM) {
        out.reference_travel_m += reference_step(counted, p, half_b);
        counted = p;
      }
      last_ref = p;
    } else {
      out.log += ",,,,";
    }
    out.log += "\n";
  }
  out.reference_travel_m += reference_step(counted, last_ref, half_b);  // the stretch after the last full step
  out.turn_rad = (right_prev - left_prev) / o.wheelbase_m;
  return out;
}

/// The wheel unit check: encoder and reference travel may differ by at most kMaxTravelRatio
/// once the run is long enough to tell.
void check_travel(const std::string& file, const ConvertedRun& out) {
  const double longer = std::max(out.encoder_travel_m, out.reference_travel_m);
  const double shorter = std::min(out.encoder_travel_m, out.reference_travel_m);
  if (longer >= kMinCheckedTravelM && !(longer <= kMaxTravelRatio * shorter)) {
    throw InputError(file, 0, "left,right",
                     "encoder travel " + format_number(out.encoder_travel_m, "%.4g") +
                         " m against reference travel " + format_number(out.reference_travel_m, "%.4g") +
                         " m (factor " + format_number(longer / std::max(shorter, 1e-300), "%.3g") +
                         ", more than " + format_number(kMaxTravelRatio) +
                         "): check the wheel unit and --left-scale/--right-scale");
  }
}

/// One log converted: read and checked, cut to the span both sources cover, re-expressed from
/// the run's start, and its travel checked.
ConvertedRun convert(const std::string& file, const CsvImportOptions& o) {
  const InputLog log = read_log(file, o);
  const auto [t_start, t_end] = run_span(file, log);
  ConvertedRun out = write_run(log, t_start, t_end, o);
  check_travel(file, out);
  return out;
}

/// The logs an input names, and in `folder` the folder that names their experiment: every
/// *.csv of a folder (sorted; none is bad input), or the file itself.
std::vector<fs::path> input_logs(const std::string& input, const fs::path& path, fs::path& folder) {
  std::vector<fs::path> files;
  if (fs::is_directory(path)) {
    folder = path.has_filename() ? path : path.parent_path();
    for (const auto& entry : fs::directory_iterator(folder)) {
      if (entry.is_regular_file() && entry.path().extension() == ".csv") files.push_back(entry.path());
    }
    if (files.empty()) throw InputError(input, 0, "", "no *.csv logs in this folder");
    std::sort(files.begin(), files.end());
  } else if (fs::is_regular_file(path)) {
    folder = path.parent_path();
    files.push_back(path);
  } else {
    throw InputError(input, 0, "", "cannot open file");
  }
  return files;
}

/// The runs of the inputs, grouped into experiments by folder name.
std::map<std::string, std::vector<fs::path>> group_runs(const std::vector<std::string>& inputs) {
  std::map<std::string, std::vector<fs::path>> experiments;
  std::map<std::string, fs::path> folder_of;  // experiment name -> the folder it came from
  for (const std::string& input : inputs) {
    const fs::path path = fs::absolute(fs::path(input)).lexically_normal();
    fs::path folder;
    const std::vector<fs::path> files = input_logs(input, path, folder);
    const std::string name = folder.filename().string();
    if (name.empty()) throw InputError(input, 0, "", "a log must sit in a folder that names its experiment");
    const auto [it, inserted] = folder_of.emplace(name, folder);
    if (!inserted && it->second != folder) {
      throw InputError(input, 0, "", "two folders are named '" + name + "' (" + it->second.string() +
                                         "); an experiment is named after its folder");
    }
    auto& list = experiments[name];
    for (const fs::path& f : files) {
      if (std::find(list.begin(), list.end(), f) == list.end()) list.push_back(f);
    }
  }
  return experiments;
}

}  // namespace

std::vector<ImportedFile> import_csv_logs(const CsvImportOptions& o,
                                          std::vector<ImportSummary>* summary) {
  if (o.inputs.empty()) throw InputError("", 0, "", "no logs given");
  if (!(o.wheelbase_m > 0)) throw InputError("", 0, "--wheelbase", "must be > 0");
  if (!(o.left_scale != 0 && std::isfinite(o.left_scale)) || !(o.right_scale != 0 && std::isfinite(o.right_scale))) {
    throw InputError("", 0, "--left-scale/--right-scale", "must be finite and not 0");
  }
  std::vector<ImportedFile> files;
  SuiteDocument doc;
  doc.comments = {"Imported by `odomcov import csv`: wheel readings x (" + format_number(o.left_scale) +
                      ", " + format_number(o.right_scale) + ") m, reference in each run's start frame."};
  doc.name = o.name;
  doc.robot = Robot{o.wheelbase_m, {o.k, o.k}};
  doc.measurement_noise = o.measurement_noise;
  for (const auto& [name, runs] : group_runs(o.inputs)) {
    SuiteDocument::Experiment ex;
    ex.name = name;
    ImportSummary sum;
    sum.experiment = name;
    sum.mean_reference_travel_m = 0.0;
    std::set<std::string> stems;
    for (const fs::path& f : runs) {
      const ConvertedRun run = convert(f.string(), o);
      const std::string rel = name + "/" + f.filename().string();
      if (!stems.insert(rel).second) throw InputError(f.string(), 0, "", "duplicate log name in " + name);
      files.push_back({rel, run.log});
      ex.logs.push_back(rel);
      sum.runs += 1;
      sum.mean_travel_m += run.encoder_travel_m;
      sum.mean_reference_travel_m += run.reference_travel_m;
      sum.mean_turn_rad += run.turn_rad;
    }
    const double n = static_cast<double>(sum.runs);
    sum.mean_travel_m /= n;
    sum.mean_reference_travel_m /= n;
    sum.mean_turn_rad /= n;
    if (summary) summary->push_back(sum);
    doc.experiments.push_back(std::move(ex));
  }
  files.push_back({"suite.yaml", suite_yaml(doc)});
  return files;
}

EncoderLog load_encoder_log(const std::string& file, double left_scale, double right_scale) {
  // A suite's log may end with heading0 (the start heading, first row): read and ignored here.
  const std::vector<std::string> wheels = {"t", "left", "right"}, reference = {"t", "left", "right", "x", "y", "theta"};
  std::vector<std::string> suite_log = reference;
  suite_log.push_back("heading0");
  const csv::Table table = csv::read_any(file, {wheels, reference, suite_log});
  EncoderLog log;
  for (const wheel_log::Row& row : wheel_log::read(file, table, wheel_log::Origin::first_row, left_scale, right_scale)) {
    if (!row.wheels) continue;  // a reference-only row
    log.t_s.push_back(row.t);
    log.left_m.push_back(row.left_m);
    log.right_m.push_back(row.right_m);
  }
  if (log.t_s.empty()) csv::fail(file, table.rows.back().line, "left,right", "no wheel readings");
  const double l0 = log.left_m.front(), r0 = log.right_m.front();
  for (double& v : log.left_m) v -= l0;
  for (double& v : log.right_m) v -= r0;
  return log;
}

}  // namespace odomcov
