// `odomcov import csv`: a user's own robot (docs/formats.md, "Generic log CSV"). One CSV per run
// with the header t,left,right,x,y,theta: cumulative wheel readings in any unit (times a scale
// per wheel to give metres) and an external reference pose in its own world frame. Part of
// odomcov::io.
#pragma once

#include <string>
#include <vector>

#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_writer.hpp"

namespace odomcov {

/// A run whose encoder travel and reference travel differ by more than this factor is refused:
/// the wheel unit or scale is wrong (mm read as m: 1000, ticks: 10^3-10^5, wheel radians: ~1/r).
inline constexpr double kMaxTravelRatio = 1.25;
/// The reference's travel is summed over steps of at least this length [m], so that its own
/// noise (about a millimetre for motion capture) does not add up over thousands of samples.
inline constexpr double kReferenceStepM = 0.02;
/// Below this travel [m] on both sides the unit check says nothing (a robot that stood still).
inline constexpr double kMinCheckedTravelM = 0.05;

struct CsvImportOptions {
  std::vector<std::string> inputs;  // log files and folders of logs (every *.csv in a folder)
  double wheelbase_m = 0.0;         // nominal wheelbase B [m], > 0
  double left_scale = 1.0;          // metres per unit of the left column
  double right_scale = 1.0;         // metres per unit of the right column
  double k = 1e-3;                  // nominal wheel noise of the suite's robot [m^(1/2)]
  MeasurementNoise measurement_noise{0.001, 0.1 * kDegToRad};  // of the reference (std-dev)
  std::string name = "csv";         // the suite's name
};

/// Reads and checks every run, then returns the suite's files: one log per run
/// (<experiment>/<file name>, in metres and in the run's start frame) and suite.yaml. The runs
/// of one folder form one experiment named after the folder. For each run:
///  * the start is the first time at which both the wheels and the reference are known; the
///    missing one is interpolated there (wheels linearly; the reference pose linearly in x, y
///    and along the shorter arc in theta);
///  * every reference pose p, theta becomes R(theta0)^T (p - p0), theta - theta0 with
///    (p0, theta0) the reference at the start;
///  * rows with only a reference get interpolated wheel readings, and the run ends at the last
///    reference pose within the wheels' time span;
///  * encoder travel sum (|dL| + |dR|)/2 and reference travel sum max(|dp|, B |dtheta| / 2)
///    (over steps of kReferenceStepM or more) must agree within kMaxTravelRatio.
/// Throws InputError (file, line, column) on any bad run, before anything is returned.
std::vector<ImportedFile> import_csv_logs(const CsvImportOptions& options,
                                          std::vector<ImportSummary>* summary = nullptr);

/// An encoder log for `predict`: the rows of a CSV with the header t,left,right (or the full
/// t,left,right,x,y,theta, whose reference columns are ignored) that have wheel readings, times
/// the scales, relative to the first row. Throws InputError on bad input.
struct EncoderLog {
  std::vector<double> t_s, left_m, right_m;
};
EncoderLog load_encoder_log(const std::string& file, double left_scale = 1.0,
                            double right_scale = 1.0);

}  // namespace odomcov
