#include "referee_options.hpp"

#include "odomcov/base/format.hpp"
#include "output.hpp"

namespace odomcov::cli {

void add_referee_options(CLI::App* cmd, RefereeOptions& o) {
  cmd->add_option("--calibration", o.calibration,
                  "How the tests are calibrated: automatic (Gaussian references where the model's "
                  "errors are Gaussian, else simulation), gaussian, or simulation (the model's own "
                  "world, simulated)")
      ->check(CLI::IsMember({"automatic", "gaussian", "simulation"}))
      ->capture_default_str();
  cmd->add_option("--replicates", o.replicates,
                  "Largest number of simulated replicates of the suite (the simulation stops "
                  "earlier once the verdict is decided)")
      ->capture_default_str();
  cmd->add_option("--seed", o.seed, "Seed of the simulated replicates")
      ->check(non_negative_integer)
      ->capture_default_str();
}

CalibrationOptions calibration_options(const RefereeOptions& o, RefereeProgress* progress) {
  if (o.replicates < 1 || o.replicates > kMaxReplicates) {
    throw UsageError("--replicates must be between 1 and " + std::to_string(kMaxReplicates) +
                     ", not " + std::to_string(o.replicates));
  }
  CalibrationOptions c;
  c.method = o.calibration == "gaussian"     ? CalibrationMethod::gaussian
             : o.calibration == "simulation" ? CalibrationMethod::simulation
                                             : CalibrationMethod::automatic;
  c.max_replicates = o.replicates;
  c.seed = o.seed;
  c.progress = progress;
  return c;
}

std::unique_ptr<ProgressBar> referee_bar(RefereeProgress& progress) {
  return std::make_unique<ProgressBar>([&progress] { return progress.done.load(); },
                                       std::function<std::int64_t()>([&progress] { return progress.target.load(); }),
                                       "replicates of the model's world");
}

std::string calibration_text(const Calibration& c) {
  if (c.method == CalibrationMethod::gaussian) {
    return "calibrated by the Gaussian references (Bonferroni over " + std::to_string(c.tests) +
           " tests): " + c.reason;
  }
  std::string text = "calibrated by simulating the model's world (" + c.reason + "): B = " +
                     std::to_string(c.replicates) + " replicates (seed " + std::to_string(c.seed) +
                     "; each test's reference from " + std::to_string(c.reference_replicates) +
                     " more), family-wise p = " + format_number(c.p_value, "%.3g");
  if (c.beyond_replicates) {
    text += " (beyond every replicate; resolution " + format_number(c.resolution, "%.2g") + ")";
  } else {
    text += " +/- " + format_number(c.p_mc_error, "%.2g") + " (Monte-Carlo; resolution " +
            format_number(c.resolution, "%.2g") + ")";
  }
  if (c.close_call) {
    text += "; a close call: the exceedance probability's interval [" + format_number(c.p_interval[0], "%.3g") +
            ", " + format_number(c.p_interval[1], "%.3g") +
            "] contains alpha at this B; more --replicates would settle it";
  }
  return text;
}

nlohmann::json calibration_json(const Calibration& c) {
  const bool simulated = c.method == CalibrationMethod::simulation;
  auto or_null = [&](auto v) { return simulated ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"calibration", calibration_name(c.method)},
          {"calibration_reason", c.reason},
          {"replicates", or_null(c.replicates)},
          {"reference_replicates", or_null(c.reference_replicates)},
          {"seed", or_null(c.seed)},
          {"tests", c.tests},
          {"p_value", c.p_value},
          {"p_value_mc_error", c.p_mc_error},
          {"p_value_interval", or_null(std::vector<double>{c.p_interval[0], c.p_interval[1]})},
          {"resolution", or_null(c.resolution)},
          {"beyond_replicates", c.beyond_replicates},
          {"close_call", c.close_call}};
}

}  // namespace odomcov::cli
