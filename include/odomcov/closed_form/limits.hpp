// The numeric domain: every magnitude the tool accepts, checked before any work starts, so that
// no count overflows, no rate underflows and no arithmetic turns non-finite (docs/bad-input.md
// lists each limit with its reason). Each check returns "" or what is wrong; the loaders attach
// file, line and key.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "odomcov/closed_form/path.hpp"

namespace odomcov {

// --- Counts ----------------------------------------------------------------------------------
/// Monte-Carlo runs of one job.
inline constexpr std::int64_t kMaxRuns = 1'000'000'000;
/// Samples of one run (ceil(duration x sample rate)).
inline constexpr std::int64_t kMaxSamplesPerRun = 100'000'000;
/// runs x samples per run; 1e12 steps is about an hour and a half on two cores.
inline constexpr double kMaxSimulationSteps = 1e12;
/// Pieces the propagation engine cuts a planned path into (model_pieces: one per 0.25 m or
/// 0.25 rad): bounds the engine's memory (about 100 bytes a piece) and time.
inline constexpr double kMaxModelPieces = 1'000'000;
/// Quadrature pieces of one order-2 prediction (1 m or 0.25 rad each, about 1000 m of line):
/// its double integral is quadratic in them (1000 pieces: about 0.7 s on one core, 10x that
/// under the sanitizers; 4000 timed out the fuzz targets). Beyond it, `run` reports order 2 as
/// untestable and commands at order 2 (compare, fit and diagnose default to it) refuse the suite.
inline constexpr std::size_t kMaxSecondOrderPieces = 1'000;
/// Runs of all experiments of one world file together (synth holds one experiment's runs and
/// writes a CSV row per run: 1e6 rows are about 70 MB).
inline constexpr std::int64_t kMaxWorldRuns = 1'000'000;
/// Points of one sweep grid (each is validated before any work starts).
inline constexpr double kMaxSweepPoints = 10'000;
/// Bytes of one input file: YAML (configs, suites, worlds, sweeps) and CSV (measurements, logs).
/// The CSV limit holds what synth writes at kMaxWorldRuns (1e6 runs: 72 MB), so that every
/// suite synth writes loads back.
inline constexpr std::int64_t kMaxYamlBytes = 16 << 20;
inline constexpr std::int64_t kMaxCsvBytes = 128 << 20;

// --- Magnitudes ------------------------------------------------------------------------------
/// Lengths: wheelbase, cumulative wheel travel, segment lengths and radii, measured positions,
/// logged wheel travel [m]. 1000 km keeps every square, product and sum far from overflow.
inline constexpr double kMaxLength_m = 1e6;
/// The shortest wheelbase [m] (1 mm).
inline constexpr double kMinWheelbase_m = 1e-3;
/// Total heading change of a path or a logged run [rad], about 16 000 turns. It bounds the
/// quadrature of the noise-induced mean (one 16-point panel per radian of a piece).
inline constexpr double kMaxTurn_rad = 1e5;
/// The lowest sample rate [Hz]: one sample in 11.6 days. Below, 1/f and the per-sample sums
/// lose their meaning long before they underflow.
inline constexpr double kMinSampleRate_hz = 1e-6;
/// Wheel noise constants k [m^(1/2)]: 1 already means a 1 m std-dev over 1 m of travel.
inline constexpr double kMaxWheelNoise = 1.0;
/// Measurement noise of the reference: position [m] as kMaxLength_m, heading [deg].
inline constexpr double kMaxMeasurementNoiseDeg = 360.0;

namespace limits {

/// A path at this wheelbase: sample rate, samples, travel at every keyframe, total turn and
/// model pieces.
std::string check_path(const Path& path, double wheelbase_m);
/// The encoder pieces of a logged run at this wheelbase: travel and total turn.
std::string check_pieces(const std::vector<ArcSegment>& pieces, double wheelbase_m);
/// Wheel noise constants k_left, k_right.
std::string check_wheel_noise(const WheelNoise& noise);
/// A wheelbase [m].
std::string check_wheelbase(double wheelbase_m);
/// A length (|value| <= kMaxLength_m).
std::string check_length(double value_m);
/// An angle, e.g. a run's start heading (|value| <= kMaxTurn_rad).
std::string check_angle(double value_rad);
/// Model pieces a path needs at this wheelbase (as model_pieces cuts it), without cutting it.
double model_piece_count(const Path& path, double wheelbase_m);

}  // namespace limits
}  // namespace odomcov
