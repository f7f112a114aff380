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

}  // namespace

std::vector<ImportedFile> import_optiodom(const OptiOdomOptions& options,
                                          std::vector<ImportSummary>* summary) {
  if (options.sessions.empty()) throw InputError("", 0, "", "no session directories given");
  // Metadata first: all sessions must agree on the nominal robot unless one is given.
  std::vector<Metadata> metas;
  for (const std::string& s : options.sessions) {
    const fs::path dir(s);
    if (!fs::is_directory(dir)) throw InputError(s, 0, "", "not a session directory");
    metas.push_back(read_metadata(dir));
  }
  double wheelbase = metas[0].wheelbase;
  std::pair<double, double> diameters{metas[0].diameters[1], metas[0].diameters[0]};  // (L, R)
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
  if (options.wheelbase_m) wheelbase = *options.wheelbase_m;
  if (options.diameters_m) diameters = *options.diameters_m;
  const double ticks = metas[0].gear * metas[0].resolution;  // encoder counts per wheel turn
  const double metres_left = M_PI * diameters.first / ticks;
  const double metres_right = M_PI * diameters.second / ticks;

  std::vector<ImportedFile> files;
  std::map<std::string, std::vector<std::string>> experiments;  // name -> log paths
  std::map<std::string, std::string> groups;                     // name -> session or day
  std::map<std::string, ImportSummary> sums;
  for (const std::string& s : options.sessions) {
    const fs::path dir = fs::path(s).lexically_normal();
    const std::string session = dir.filename().string();
    const std::string type = dir.parent_path().filename().string();
    std::vector<fs::path> run_files;
    for (const auto& entry : fs::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind(session + "_run-", 0) == 0 && entry.path().extension() == ".csv") {
        run_files.push_back(entry.path());
      }
    }
    std::sort(run_files.begin(), run_files.end());
    if (run_files.empty()) throw InputError(s, 0, "", "no run files (" + session + "_run-NN.csv)");
    for (const fs::path& run_file : run_files) {
      // Columns: time, x_gt, y_gt, th_gt, odoR, odoL (ticks in the cycle ending at the row).
      const csv::Table table = csv::read_headerless(run_file.string(), 6);
      std::string log = "t,left,right,x,y,theta\n";
      double left = 0, right = 0, t_prev = -HUGE_VAL, turned = 0, travel = 0;
      std::vector<ArcSegment> pieces;  // for the suite loader's own limits, checked here first
      for (std::size_t i = 0; i < table.rows.size(); ++i) {
        const csv::Row& row = table.rows[i];
        const double t = row.number(0);
        const Vector3 reference(row.number(1), row.number(2), row.number(3));  // every row checked
        if (!(t > t_prev)) csv::fail(run_file.string(), row.line, "time", "time must increase strictly");
        t_prev = t;
        const double dl = row.number(5) * metres_left, dr = row.number(4) * metres_right;
        left += dl;
        right += dr;
        pieces.push_back({dl, dr});
        // The loader's checks of every value written (limits.hpp), so the suite always loads.
        for (const auto& [value, column] : {std::pair{left, "left"}, std::pair{right, "right"}}) {
          if (const std::string e = limits::check_length(value); !e.empty()) csv::fail(run_file.string(), row.line, column, e);
        }
        turned += (dr - dl) / wheelbase;
        travel += std::abs(0.5 * (dl + dr));
        // %.17g: Unix timestamps (1.7e9 s at 20 Hz) need more than ten digits to stay distinct.
        log += format_number(t, "%.17g") + "," + format_number(left, "%.17g") + "," +
               format_number(right, "%.17g");
        if (i + 1 == table.rows.size()) {
          for (int k = 0; k < 3; ++k) {
            if (const std::string e = limits::check_length(reference[k]); !e.empty()) {
              csv::fail(run_file.string(), row.line, k == 0 ? "x" : k == 1 ? "y" : "theta", e);
            }
          }
          log += "," + format_number(reference.x()) + "," + format_number(reference.y()) + "," + format_number(reference.z());
        } else {
          log += ",,,";
        }
        log += "\n";
      }
      if (table.rows.size() < 2) throw InputError(run_file.string(), 0, "", "a run needs two rows or more");
      // The written suite must load: a run beyond the loader's limits is refused here.
      if (const std::string e = limits::check_pieces(pieces, wheelbase); !e.empty()) {
        throw InputError(run_file.string(), 0, "", e);
      }
      std::string direction;
      if (type == "square" || type == "circular" || type == "ivanjko") {
        direction = std::abs(turned) < kStraightBelowRad ? "-straight" : turned < 0 ? "-cw" : "-ccw";
      }
      const std::string experiment = type + "-" + session + direction;
      const std::string stem = run_file.stem().string();
      const std::string rel = type + "/" + session + "/" + stem.substr(session.size() + 1) + ".csv";
      files.push_back({rel, log});
      experiments[experiment].push_back(rel);
      groups[experiment] = options.group == OptiOdomGroup::day ? recording_day(session) : session;
      ImportSummary& sum = sums[experiment];
      sum.experiment = experiment;
      sum.runs += 1;
      sum.mean_travel_m += travel;
      sum.mean_turn_rad += turned;
    }
  }
  SuiteDocument doc;
  doc.comments = {"Imported by `odomcov import optiodom` from the OptiOdom recordings",
                  "(Sousa et al., J Intell Robot Syst 105:39, 2022; MIT licence).",
                  "Ticks to metres: pi D / (" + format_number(metas[0].gear) + " x " +
                      format_number(metas[0].resolution) + "), no quadrature factor."};
  doc.name = options.name;
  doc.robot = Robot{wheelbase, {options.k, options.k}};
  doc.measurement_noise = options.measurement_noise;
  for (const auto& [name, logs] : experiments) {
    doc.experiments.push_back({name, "", "", logs, groups[name]});
  }
  const std::string yaml = suite_yaml(doc);
  files.push_back({"suite.yaml", yaml});
  if (summary) {
    for (auto& [name, sum] : sums) {
      sum.mean_travel_m /= static_cast<double>(sum.runs);
      sum.mean_turn_rad /= static_cast<double>(sum.runs);
      summary->push_back(sum);
    }
  }
  return files;
}

}  // namespace odomcov
