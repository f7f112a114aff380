// `import csv` on logs constructed from a known path: the reference given in a rotated and
// translated world frame, the wheels in encoder ticks. After the import, each run's measured end
// pose must be the known start-frame pose, so its error against the odometry is zero.
#include "odomcov/io/csv_import.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "odomcov/base/error.hpp"
#include "test_util.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_io.hpp"

namespace odomcov {
namespace {

namespace fs = std::filesystem;

constexpr double kWheelbaseM = 0.3;
constexpr double kMetresPerTick = 2.0 * M_PI * 0.05 / 4096.0;  // r = 5 cm, 4096 ticks per turn
const Vector3 kWorldFromStart(3.2, -1.7, 2.5);                 // the motion-capture frame

/// Wheel travel linear in time between keyframes (t, L, R), so each interval is an arc.
struct Trajectory {
  std::vector<Keyframe> keyframes;

  Keyframe wheels(double t) const {
    for (std::size_t i = 1; i < keyframes.size(); ++i) {
      const Keyframe& a = keyframes[i - 1];
      const Keyframe& b = keyframes[i];
      if (t <= b.t_s) {
        const double f = (t - a.t_s) / (b.t_s - a.t_s);
        return {t, a.left_m + f * (b.left_m - a.left_m), a.right_m + f * (b.right_m - a.right_m)};
      }
    }
    return keyframes.back();
  }
  /// The true pose at t in the frame of the first keyframe: exact arc integration.
  Vector3 pose(double t) const {
    Vector3 p = Vector3::Zero();
    Keyframe prev = keyframes.front();
    for (std::size_t i = 1; i < keyframes.size() && prev.t_s < t; ++i) {
      const Keyframe next = keyframes[i].t_s <= t ? keyframes[i] : wheels(t);
      p = drive(p, {next.left_m - prev.left_m, next.right_m - prev.right_m}, kWheelbaseM);
      prev = next;
    }
    return p;
  }
};

/// Line 1 m, arc R = 0.5 m through 120 deg, spin -200 deg, line 0.6 m: keyframes at multiples
/// of 20 ms, the wheel sampling period, so every logged interval is one arc.
Trajectory test_path(double t0 = 0.0) {
  Trajectory tr;
  const double B = kWheelbaseM;
  double L = 10.0, R = 10.0;  // the encoders do not start at 0
  tr.keyframes.push_back({t0, L, R});
  auto add = [&](double duration, double dl, double dr) {
    L += dl, R += dr;
    tr.keyframes.push_back({tr.keyframes.back().t_s + duration, L, R});
  };
  add(2.0, 1.0, 1.0);
  const double a = 120 * M_PI / 180;
  add(2.4, a * (0.5 - B / 2), a * (0.5 + B / 2));
  const double s = -200 * M_PI / 180;
  add(1.6, -s * B / 2, s * B / 2);
  add(1.2, 0.6, 0.6);
  return tr;
}

std::string num(double v) { return format_number(v, "%.17g"); }

/// Reference in the world frame, theta wrapped to (-pi, pi] as a motion-capture system gives it.
std::string reference_cells(const Trajectory& tr, double t) {
  const Vector3 w = compose(kWorldFromStart, tr.pose(t));
  return num(w.x()) + "," + num(w.y()) + "," + num(wrap_angle(w.z()));
}

class CsvImport : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::scratch_dir("odomcov_csv_import");
    fs::create_directories(dir_ / "lab");
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& rel, const std::string& text) {
    const fs::path p = dir_ / rel;
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
    return p.string();
  }
  /// Imports, writes the suite's files and loads the suite back.
  Suite import(const CsvImportOptions& o) {
    const fs::path out = dir_ / "out";
    for (const ImportedFile& f : import_csv_logs(o)) {
      fs::create_directories((out / f.path).parent_path());
      std::ofstream(out / f.path) << f.text;
    }
    return load_suite((out / "suite.yaml").string());
  }
  fs::path dir_;
};

TEST_F(CsvImport, WorldFrameReferenceAndTicks) {
  const Trajectory tr = test_path();
  std::string text = "t,left,right,x,y,theta\n";
  for (int k = 0; k * 0.02 <= tr.keyframes.back().t_s + 1e-9; ++k) {
    const double t = k * 0.02;
    const Keyframe w = tr.wheels(t);
    text += num(t) + "," + num(w.left_m / kMetresPerTick) + "," + num(w.right_m / kMetresPerTick);
    // the reference at 10 Hz, and always on the last row
    text += (k % 5 == 0 || t + 0.02 > tr.keyframes.back().t_s + 1e-9) ? "," + reference_cells(tr, t) : ",,,";
    text += "\n";
  }
  write("lab/run-01.csv", text);
  CsvImportOptions o;
  o.inputs = {(dir_ / "lab").string()};
  o.wheelbase_m = kWheelbaseM;
  o.left_scale = o.right_scale = kMetresPerTick;
  std::vector<ImportSummary> summary;
  import_csv_logs(o, &summary);
  ASSERT_EQ(summary.size(), 1u);
  EXPECT_EQ(summary[0].experiment, "lab");
  // mean wheel travel: 1 + 0.5 * 2.094 (the arc's centre travel) + 0.15 * 3.491 (spin) + 0.6
  const double travel = 1.0 + 0.5 * 120 * M_PI / 180 + 0.15 * 200 * M_PI / 180 + 0.6;
  EXPECT_NEAR(summary[0].mean_travel_m, travel, 1e-9);
  EXPECT_NEAR(summary[0].mean_reference_travel_m, travel, 0.01 * travel);

  const Suite suite = import(o);
  ASSERT_EQ(suite.experiments.size(), 1u);
  const SuiteExperiment& ex = suite.experiments[0];
  EXPECT_EQ(ex.name, "lab");
  ASSERT_EQ(ex.runs.size(), 1u);
  const Vector3 expected = tr.pose(tr.keyframes.back().t_s);  // start frame
  EXPECT_NEAR(ex.runs[0].measured.x(), expected.x(), 1e-9);
  EXPECT_NEAR(ex.runs[0].measured.y(), expected.y(), 1e-9);
  EXPECT_NEAR(wrap_angle(ex.runs[0].measured.z() - expected.z()), 0.0, 1e-9);
  const Vector3 error = run_error(ex, ex.runs[0], kWheelbaseM);
  EXPECT_LT(error.cwiseAbs().maxCoeff(), 1e-9) << error.transpose();
}

// Unix timestamps at 1 kHz: 1.7e9 s with millisecond steps needs 13 significant digits. The
// importer writes times (and every other number) at full precision (%.17g), so consecutive rows
// stay distinct and the suite loads back; at %.12g they became equal ("time must increase").
TEST_F(CsvImport, UnixTimestampsAtOneKilohertzLoadBack) {
  const double t0 = 1.7e9;
  const Trajectory tr = test_path(t0);
  std::string text = "t,left,right,x,y,theta\n";
  const double end = tr.keyframes.back().t_s - t0;
  for (int k = 0; k * 0.001 <= end + 1e-9; ++k) {
    const double t = t0 + k * 0.001;
    const Keyframe w = tr.wheels(t);
    text += num(t) + "," + num(w.left_m) + "," + num(w.right_m);
    text += (k % 20 == 0 || (k + 1) * 0.001 > end + 1e-9) ? "," + reference_cells(tr, t) : ",,,";
    text += "\n";
  }
  write("lab/run-01.csv", text);
  CsvImportOptions o;
  o.inputs = {(dir_ / "lab").string()};
  o.wheelbase_m = kWheelbaseM;
  const Suite suite = import(o);
  ASSERT_EQ(suite.experiments.size(), 1u);
  const SuiteRun& run = suite.experiments[0].runs.at(0);
  EXPECT_GT(run.pieces.size(), 7000u);
  for (double dt : run.durations_s) ASSERT_GT(dt, 0.0);
  const Vector3 error = run_error(suite.experiments[0], run, kWheelbaseM);
  EXPECT_LT(error.cwiseAbs().maxCoeff(), 1e-6) << error.transpose();
}

/// The reference starts before the wheels and runs on its own clock (reference-only rows): the
/// start pose is interpolated at the first wheel reading, on an arc whose world heading crosses
/// +-pi there, and the wheels are interpolated at every reference row.
TEST_F(CsvImport, InterpolatedStartAcrossPi) {
  Trajectory tr;
  // A left arc of radius 0.4 m at 0.3 m/s from t = -1 s; world heading pi at t = 0.
  const double B = kWheelbaseM, radius = 0.4, v = 0.3;
  const double rate = v / radius;  // rad/s
  tr.keyframes = {{-1.0, 0.0, 0.0}};
  for (int i = 1; i <= 250; ++i) {
    const double t = -1.0 + 0.02 * i;
    tr.keyframes.push_back({t, (t + 1.0) * rate * (radius - B / 2), (t + 1.0) * rate * (radius + B / 2)});
  }
  // world frame chosen so that the heading at t = 0 is exactly pi
  const Vector3 world_from_start(1.0, 2.0, M_PI - tr.pose(0.0).z());
  auto ref = [&](double t) {
    const Vector3 w = compose(world_from_start, tr.pose(t));
    return num(w.x()) + "," + num(w.y()) + "," + num(wrap_angle(w.z()));
  };
  std::string text = "t,left,right,x,y,theta\n";
  text += num(-0.013) + ",,," + ref(-0.013) + "\n";  // the reference starts first
  for (int k = 0; k <= 200; ++k) {
    const double t = 0.02 * k;
    const Keyframe w = tr.wheels(t);
    text += num(t) + "," + num(w.left_m) + "," + num(w.right_m) + ",,,\n";
    if (k < 200) text += num(t + 0.007) + ",,," + ref(t + 0.007) + "\n";
  }
  write("arc/run-01.csv", text);
  CsvImportOptions o;
  o.inputs = {(dir_ / "arc" / "run-01.csv").string()};
  o.wheelbase_m = B;
  const Suite suite = import(o);
  const SuiteExperiment& ex = suite.experiments.at(0);
  EXPECT_EQ(ex.name, "arc");
  // expected: the last reference (t = 3.987) relative to the true pose at t = 0
  const Vector3 p0 = tr.pose(0.0), p1 = tr.pose(3.987);
  const double c = std::cos(p0.z()), s = std::sin(p0.z());
  const Vector3 expected(c * (p1.x() - p0.x()) + s * (p1.y() - p0.y()),
                         -s * (p1.x() - p0.x()) + c * (p1.y() - p0.y()), p1.z() - p0.z());
  // Linear interpolation of the start between samples 20 ms apart on a 0.4 m arc: the chord
  // error is v^2 dt^2 / (8 R) ~ 1e-5 m, and the heading exact (linear in time on an arc).
  const Vector3 measured = ex.runs.at(0).measured;
  EXPECT_NEAR(measured.x(), expected.x(), 1e-4);
  EXPECT_NEAR(measured.y(), expected.y(), 1e-4);
  EXPECT_NEAR(measured.z(), expected.z(), 1e-9);  // short way round, and unwrapped
  EXPECT_LT(run_error(ex, ex.runs[0], B).cwiseAbs().maxCoeff(), 1e-4);
}

TEST_F(CsvImport, WrongUnitIsRefusedAndScalesFixIt) {
  const Trajectory tr = test_path();
  std::string text = "t,left,right,x,y,theta\n";
  for (int k = 0; k * 0.02 <= tr.keyframes.back().t_s + 1e-9; ++k) {
    const Keyframe w = tr.wheels(k * 0.02);
    text += num(k * 0.02) + "," + num(1000 * w.left_m) + "," + num(1000 * w.right_m) + "," +
            reference_cells(tr, k * 0.02) + "\n";
  }
  const std::string file = write("mm/run-01.csv", text);
  CsvImportOptions o;
  o.inputs = {file};
  o.wheelbase_m = kWheelbaseM;
  try {
    import_csv_logs(o);
    FAIL() << "millimetres read as metres were accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), file);
    EXPECT_NE(e.message().find("encoder travel 3"), std::string::npos) << e.what();  // 3141 m
    EXPECT_NE(e.message().find("reference travel 3.1"), std::string::npos) << e.what();
  }
  o.left_scale = o.right_scale = 1e-3;
  EXPECT_LT(run_error(import(o).experiments[0], import(o).experiments[0].runs[0], kWheelbaseM)
                .cwiseAbs()
                .maxCoeff(),
            1e-9);
}

TEST_F(CsvImport, ExperimentsAreFolders) {
  const Trajectory tr = test_path();
  std::string text = "t,left,right,x,y,theta\n";
  for (int k = 0; k * 0.02 <= tr.keyframes.back().t_s + 1e-9; ++k) {
    const Keyframe w = tr.wheels(k * 0.02);
    text += num(k * 0.02) + "," + num(w.left_m) + "," + num(w.right_m) + "," +
            reference_cells(tr, k * 0.02) + "\n";
  }
  write("day one/a.csv", text);
  write("day one/b.csv", text);
  write("other/c.csv", text);
  CsvImportOptions o;
  o.inputs = {(dir_ / "day one").string(), (dir_ / "other" / "c.csv").string()};
  o.wheelbase_m = kWheelbaseM;
  const Suite suite = import(o);
  ASSERT_EQ(suite.experiments.size(), 2u);
  EXPECT_EQ(suite.experiments[0].name, "day one");  // quoted in the YAML, read back unchanged
  EXPECT_EQ(suite.experiments[0].runs.size(), 2u);
  EXPECT_EQ(suite.experiments[1].name, "other");
  EXPECT_EQ(suite.experiments[1].runs.size(), 1u);
}

}  // namespace
}  // namespace odomcov
