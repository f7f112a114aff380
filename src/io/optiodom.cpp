#include "odomcov/io/optiodom.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>

#include <yaml-cpp/yaml.h>

#include "io/csv.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/io/suite_writer.hpp"

namespace odomcov {
namespace {

namespace fs = std::filesystem;

/// A run whose total encoder heading change is below this is a straight run.
constexpr double kStraightBelowRad = 0.5;
/// Sessions started before this hour belong to the previous evening's recording day.
constexpr int kSessionDayStartsHour = 6;

struct Metadata {
  std::string file;
  double gear = 0, resolution = 0, wheelbase = 0;
  std::vector<double> diameters;  // D1 (first encoder column, odoR), D2 (odoL)
};

Metadata read_metadata(const fs::path& dir) {
  const std::string session = dir.filename().string();
  const fs::path file = dir / (session + "_metadata.csv");
  const csv::Table table = csv::read_headerless(file.string(), 1);
  Metadata m;
  m.file = file.string();
  std::map<std::string, const csv::Row*> rows;
  for (const csv::Row& row : table.rows) rows[row.text(0)] = &row;
  auto need = [&](const char* key) -> const csv::Row& {
    const auto it = rows.find(key);
    if (it == rows.end()) throw InputError(m.file, 0, key, "missing metadata row");
    return *it->second;
  };
  if (need("type").cells.size() < 2 || need("type").text(1) != "diff") {
    throw InputError(m.file, need("type").line, "type", "only differential-drive (diff) data");
  }
  auto positive = [&](const char* key) {
    const csv::Row& row = need(key);
    if (row.cells.size() < 2) csv::fail(m.file, row.line, key, "missing value");
    const double v = row.number(1);
    if (!(v > 0)) csv::fail(m.file, row.line, key, "must be > 0");
    return v;
  };
  m.gear = positive("ngear");
  m.resolution = positive("encRes");
  m.wheelbase = positive("Li");
  const csv::Row& di = need("Di");
  for (std::size_t i = 1; i < di.cells.size() && !di.empty(i); ++i) m.diameters.push_back(di.number(i));
  if (m.diameters.size() != 2) csv::fail(m.file, di.line, "Di", "expected two wheel diameters");
  return m;
}

/// The recording day of a session directory named DDMMYYYYhhmm (its start time): the evening
/// it belongs to, as YYYY-MM-DD, a session started before 06:00 belonging to the evening before
/// (the December and January recordings run past midnight). Any other name is its own day.
std::string recording_day(const std::string& name) {
  if (name.size() != 12 || name.find_first_not_of("0123456789") != std::string::npos) return name;
  std::tm tm{};
  tm.tm_mday = std::stoi(name.substr(0, 2));
  tm.tm_mon = std::stoi(name.substr(2, 2)) - 1;
  tm.tm_year = std::stoi(name.substr(4, 4)) - 1900;
  tm.tm_hour = 12;  // noon: no daylight-saving edge moves the date
  if (std::stoi(name.substr(8, 2)) < kSessionDayStartsHour) tm.tm_mday -= 1;
  tm.tm_isdst = -1;
  std::mktime(&tm);  // normalises the day before the 1st
  char text[16];
  std::strftime(text, sizeof text, "%Y-%m-%d", &tm);
  return text;
}

/// Every session's metadata, read before any run file: all must exist and be directories.
std::vector<Metadata> read_all_metadata(const std::vector<std::string>& sessions) {
  std::vector<Metadata> metas;
  for (const std::string& s : sessions) {
    const fs::path dir(s);
    if (!fs::is_directory(dir)) throw InputError(s, 0, "", "not a session directory");
    metas.push_back(read_metadata(dir));
  }
  return metas;
}

/// A session's wheel diameters as (left, right) [m]: Di gives odoR's wheel first.
std::pair<double, double> left_right_diameters(const Metadata& m) { return {m.diameters[1], m.diameters[0]}; }

/// The nominal robot of the suite and the ticks-to-metres factors of the encoders.
struct Nominal {
  double wheelbase = 0;                      // [m]
  std::pair<double, double> diameters;       // (left, right) [m]
  double metres_left = 0, metres_right = 0;  // wheel travel per encoder tick [m]
};

/// The sessions must agree on the nominal robot (wheelbase, wheel diameters) unless the options
/// choose it, and always on the gear ratio and encoder resolution. The first disagreeing
/// session's metadata file is named.
void check_sessions_agree(const std::vector<Metadata>& metas, const OptiOdomOptions& options) {
  const double wheelbase = metas[0].wheelbase;
  const std::pair<double, double> diameters = left_right_diameters(metas[0]);
  for (const Metadata& m : metas) {
    if (!options.wheelbase_m && m.wheelbase != wheelbase) {
      throw InputError(m.file, 0, "Li",
                       "sessions disagree on the wheelbase (" + format_number(wheelbase) + " and " +
                           format_number(m.wheelbase) + "); choose the nominal robot with --wheelbase");
    }
    if (!options.diameters_m &&
        (m.diameters[1] != diameters.first || m.diameters[0] != diameters.second)) {
      throw InputError(m.file, 0, "Di",
                       "sessions disagree on the wheel diameters; choose them with --diameters");
    }
    if (m.gear != metas[0].gear || m.resolution != metas[0].resolution) {
      throw InputError(m.file, 0, "ngear", "sessions disagree on the gear ratio or encoder resolution");
    }
  }
}

/// The nominal robot: the options' wheelbase and diameters, else the (agreeing) metadata's;
/// ticks become metres as pi D / (ngear encRes).
Nominal nominal_robot(const std::vector<Metadata>& metas, const OptiOdomOptions& options) {
  check_sessions_agree(metas, options);
  Nominal robot;
  robot.wheelbase = options.wheelbase_m ? *options.wheelbase_m : metas[0].wheelbase;
  robot.diameters = options.diameters_m ? *options.diameters_m : left_right_diameters(metas[0]);
  const double ticks = metas[0].gear * metas[0].resolution;  // encoder counts per wheel turn
  robot.metres_left = M_PI * robot.diameters.first / ticks;
  robot.metres_right = M_PI * robot.diameters.second / ticks;
  return robot;
}

/// A session's run files (SESSION_run-NN.csv), sorted; none is bad input.
std::vector<fs::path> run_files_of(const std::string& s, const fs::path& dir, const std::string& session) {
  std::vector<fs::path> run_files;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(session + "_run-", 0) == 0 && entry.path().extension() == ".csv") {
      run_files.push_back(entry.path());
    }
  }
  std::sort(run_files.begin(), run_files.end());
  if (run_files.empty()) throw InputError(s, 0, "", "no run files (" + session + "_run-NN.csv)");
  return run_files;
}

/// One row of a run file: time [s], the cumulative wheel travel since the first row [m], and
/// the OptiTrack pose (world frame, x and y [m], theta [rad]).
struct RunRow {
  int line = 0;
  double t = 0, left = 0, right = 0;
  Vector3 reference = Vector3::Zero();
};

/// A run file read and checked row by row, with what the importer reports of it.
struct Run {
  std::vector<RunRow> rows;
  std::vector<ArcSegment> pieces;  // per row [m], for the suite loader's own limits
  double turned = 0;  // encoder heading change [rad]
  double travel = 0;  // encoder centre travel, sum |dL + dR|/2 [m]
};

/// Reads a run file (columns: time, x_gt, y_gt, th_gt, odoR, odoL, the ticks in the cycle
/// ending at the row): every value parsed, time strictly increasing, and the cumulative
/// travel within the loader's limits (limits.hpp), so the written suite always loads.
Run read_run(const fs::path& run_file, const Nominal& robot) {
  const csv::Table table = csv::read_headerless(run_file.string(), 6);
  Run run;
  double left = 0, right = 0, t_prev = -HUGE_VAL;
  for (const csv::Row& row : table.rows) {
    const double t = row.number(0);
    const Vector3 reference(row.number(1), row.number(2), row.number(3));  // every row checked
    if (!(t > t_prev)) csv::fail(run_file.string(), row.line, "time", "time must increase strictly");
    t_prev = t;
    const double dl = row.number(5) * robot.metres_left, dr = row.number(4) * robot.metres_right;
    left += dl;
    right += dr;
    run.pieces.push_back({dl, dr});
    for (const auto& [value, column] : {std::pair{left, "left"}, std::pair{right, "right"}}) {
      if (const std::string e = limits::check_length(value); !e.empty()) csv::fail(run_file.string(), row.line, column, e);
    }
    run.turned += (dr - dl) / robot.wheelbase;
    run.travel += std::abs(0.5 * (dl + dr));
    run.rows.push_back({row.line, t, left, right, reference});
  }
  return run;
}

/// The run's end pose in its start frame: R(theta0)^T (p - p0), theta - theta0, with
/// (p0, theta0) the first row's reference pose.
Vector3 end_in_start_frame(const Run& run) {
  const Vector3& start = run.rows.front().reference;
  const Vector3& end = run.rows.back().reference;
  const double c = std::cos(start.z()), s = std::sin(start.z());
  const double dx = end.x() - start.x(), dy = end.y() - start.y();
  return {c * dx + s * dy, -s * dx + c * dy, end.z() - start.z()};
}

/// What must hold of a whole run: its end pose in its start frame (the only one written) and
/// its start heading within the loader's limits, two rows or more, and its pieces within the
/// loader's limits at the wheelbase.
void check_run(const fs::path& run_file, const Run& run, double wheelbase) {
  if (!run.rows.empty()) {
    const RunRow& last = run.rows.back();
    const Vector3 end = end_in_start_frame(run);
    const char* const columns[3] = {"x", "y", "theta"};
    for (int k = 0; k < 3; ++k) {
      if (const std::string e = limits::check_length(end[k]); !e.empty()) {
        csv::fail(run_file.string(), last.line, columns[k], e);
      }
    }
  }
  if (run.rows.size() < 2) throw InputError(run_file.string(), 0, "", "a run needs two rows or more");
  // The written suite must load: a run beyond the loader's limits is refused here.
  if (const std::string e = limits::check_pieces(run.pieces, wheelbase); !e.empty()) {
    throw InputError(run_file.string(), 0, "", e);
  }
}

/// The suite's log of a run: t and the cumulative left and right travel per row, the
/// OptiTrack end pose in the run's start frame (the first row's pose) in the last row only, and
/// the start heading in OptiTrack's frame (the first row's theta) as heading0 on the first row.
/// The published recordings give every pose relative to the run's start, so their first row is
/// (0, 0, 0): the end pose is the recorded one and heading0 is 0 (the absolute heading is not
/// in the data).
std::string run_log(const Run& run) {
  std::string log = "t,left,right,x,y,theta,heading0\n";
  const Vector3& start = run.rows.front().reference;
  for (std::size_t i = 0; i < run.rows.size(); ++i) {
    const RunRow& row = run.rows[i];
    // %.17g: Unix timestamps (1.7e9 s at 20 Hz) need more than ten digits to stay distinct.
    log += format_number(row.t, "%.17g") + "," + format_number(row.left, "%.17g") + "," +
           format_number(row.right, "%.17g");
    if (i + 1 == run.rows.size()) {
      const Vector3 end = end_in_start_frame(run);
      log += "," + format_number(end.x()) + "," + format_number(end.y()) + "," + format_number(end.z());
    } else {
      log += ",,,";
    }
    log += i == 0 ? "," + format_number(wrap_angle(start.z()), "%.17g") + "\n" : ",\n";
  }
  return log;
}

/// The experiment of a run: path type and session, and for the calibration paths the turning
/// direction from the sign of the encoders' total heading change `turned` [rad].
std::string experiment_name(const std::string& type, const std::string& session, double turned) {
  std::string direction;
  if (type == "square" || type == "circular" || type == "ivanjko") {
    direction = std::abs(turned) < kStraightBelowRad ? "-straight" : turned < 0 ? "-cw" : "-ccw";
  }
  return type + "-" + session + direction;
}

/// The import so far: the run logs, and per experiment its logs, group and summary.
struct Imported {
  std::vector<ImportedFile> files;
  std::map<std::string, std::vector<std::string>> experiments;  // name -> log paths
  std::map<std::string, std::string> groups;                     // name -> session or day
  std::map<std::string, ImportSummary> sums;
};

/// Reads, checks and converts every run of a session directory into `out`.
void import_session(const std::string& s, const Nominal& robot, const OptiOdomOptions& options,
                    Imported& out) {
  const fs::path dir = fs::path(s).lexically_normal();
  const std::string session = dir.filename().string();
  const std::string type = dir.parent_path().filename().string();
  for (const fs::path& run_file : run_files_of(s, dir, session)) {
    const Run run = read_run(run_file, robot);
    check_run(run_file, run, robot.wheelbase);
    const std::string experiment = experiment_name(type, session, run.turned);
    const std::string stem = run_file.stem().string();
    const std::string rel = type + "/" + session + "/" + stem.substr(session.size() + 1) + ".csv";
    out.files.push_back({rel, run_log(run)});
    out.experiments[experiment].push_back(rel);
    out.groups[experiment] = options.group == OptiOdomGroup::day ? recording_day(session) : session;
    ImportSummary& sum = out.sums[experiment];
    sum.experiment = experiment;
    sum.runs += 1;
    sum.mean_travel_m += run.travel;
    sum.mean_turn_rad += run.turned;
  }
}

/// The suite.yaml text: the nominal robot and one logged experiment per name, with its group.
std::string suite_text(const Metadata& meta, const Nominal& robot, const OptiOdomOptions& options,
                       const Imported& imported) {
  SuiteDocument doc;
  doc.comments = {"Imported by `odomcov import optiodom` from the OptiOdom recordings",
                  "(Sousa et al., J Intell Robot Syst 105:39, 2022; MIT licence).",
                  "Ticks to metres: pi D / (" + format_number(meta.gear) + " x " +
                      format_number(meta.resolution) + "), no quadrature factor."};
  doc.name = options.name;
  doc.robot = Robot{robot.wheelbase, {options.k, options.k}};
  doc.measurement_noise = options.measurement_noise;
  for (const auto& [name, logs] : imported.experiments) {
    doc.experiments.push_back({name, "", "", logs, imported.groups.at(name), {}});
  }
  return suite_yaml(doc);
}

}  // namespace

std::vector<ImportedFile> import_optiodom(const OptiOdomOptions& options,
                                          std::vector<ImportSummary>* summary) {
  if (options.sessions.empty()) throw InputError("", 0, "", "no session directories given");
  // Metadata first: all sessions must agree on the nominal robot unless one is given.
  const std::vector<Metadata> metas = read_all_metadata(options.sessions);
  const Nominal robot = nominal_robot(metas, options);
  Imported imported;
  for (const std::string& s : options.sessions) import_session(s, robot, options, imported);
  const std::string yaml = suite_text(metas[0], robot, options, imported);
  imported.files.push_back({"suite.yaml", yaml});
  if (summary) {
    for (auto& [name, sum] : imported.sums) {
      sum.mean_travel_m /= static_cast<double>(sum.runs);
      sum.mean_turn_rad /= static_cast<double>(sum.runs);
      summary->push_back(sum);
    }
  }
  return imported.files;
}

}  // namespace odomcov
