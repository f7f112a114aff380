// Private to odomcov::io: the YAML parsers behind load_config, load_suite, load_world and
// load_sweep. They take yaml-cpp nodes, so they stay out of the public headers.
#pragma once

#include <string>

#include "odomcov/measurement/config.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/config_io.hpp"
#include "odomcov/io/suite_io.hpp"

namespace YAML {
class Node;
}

namespace odomcov {

/// Validates an already-parsed YAML tree (used by `sweep`, which edits keys before parsing).
Config parse_config(const YAML::Node& root, const std::string& file);

/// Parses the `path` block (sample_rate plus keyframes or segments), shared with measurement
/// suites. `key` is the block's dotted key path for messages.
Path parse_path(const YAML::Node& node, const std::string& file, const std::string& key,
                double wheelbase_m);

/// Parses an effect list (single-key maps, docs/formats.md "Effect catalogue"); `key` for messages.
EffectList parse_effects(const YAML::Node& node, const std::string& file, const std::string& key);

/// Parses a `world` block {effects, k_left, k_right}; missing k's default to `nominal`.
World parse_world(const YAML::Node& node, const std::string& file, const std::string& key,
                  const WheelNoise& nominal);

/// Parses a `robot` block {wheelbase, k_left, k_right}.
Robot parse_robot(const YAML::Node& node, const std::string& file, const std::string& key);

/// Parses a `measurement_noise` block {xy [m], theta_deg}, both optional (0) and >= 0; `key`
/// for messages. Suites and worlds share it.
MeasurementNoise parse_measurement_noise(const YAML::Node& node, const std::string& file,
                                         const std::string& key);

}  // namespace odomcov
