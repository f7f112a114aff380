// The referee of compare's verdicts: the model's own world, simulated run by run. Every run of
// a suite is driven again as the model says the robot behaves: its wheel noise, its effects as
// the world (per-run radii, bumps, slip, ...), the reference's measurement noise and, with
// group_variation, a new draw of the varied parameter per group and replicate. Each replicate
// is a suite the model explains by construction; compare computes its statistics on many of
// them to learn their distribution under the model (docs/diagnose.md, "How compare decides").
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "odomcov/measurement/suite.hpp"

namespace odomcov {

class ModelWorld {
 public:
  /// Builds one simulator per planned-path experiment and per logged run (a logged run steps
  /// through its own encoder pieces and durations, one sample per piece: Simulator's logged-run
  /// constructor; when an effect uses the absolute heading, one per run of a planned path too,
  /// each from the run's start heading), and group_variation's interpolants. Throws EffectError when the model's
  /// effects cannot be simulated on a run (as synth would refuse them).
  ModelWorld(const Suite& suite, const SuiteModel& model, std::uint64_t seed);
  ~ModelWorld();
  ModelWorld(ModelWorld&&) noexcept;
  ModelWorld& operator=(ModelWorld&&) noexcept;

  /// The errors (measured - odometry, start frame, theta wrapped) of replicates first ..
  /// first + count - 1, replicate by replicate, each with every run of the suite in order
  /// (experiment by experiment): out[(b - first) * runs() + i]. Replicate b's numbers depend
  /// only on (seed, b), never on `count`, the batch it comes in or the thread count.
  void errors(std::int64_t first, std::int64_t count, std::vector<Vector3>& out) const;

  std::size_t runs() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace odomcov
