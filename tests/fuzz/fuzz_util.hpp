// Shared pieces of the libFuzzer targets (docs/bad-input.md, "Testing it").
//
// One fuzz input can hold several files. The first section is the target's main file; each line
//   #@ NAME
// starts a new section that becomes the file NAME next to it (NAME: letters, digits, '_', '.',
// '-', at most 64 characters, not starting with '.'; a section with any other name is dropped).
// The same format is unpacked by tests/hostile/unpack.sh to replay a corpus through the CLI.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "odomcov/io/suite_writer.hpp"

namespace odomcov::fuzz {

/// Writes the sections of `data` into a fresh per-process directory and returns it; the main
/// section is written as `main_name`.
std::filesystem::path unpack(const std::uint8_t* data, std::size_t size, const std::string& main_name);

/// A second fresh per-process directory (for what a target writes, e.g. synth's suite).
std::filesystem::path scratch_dir(const std::string& name);

/// Writes `text` to `path`.
void write_text(const std::filesystem::path& path, const std::string& text);

/// Stops the fuzzer with a message: an invariant of the target failed (e.g. what synth wrote does
/// not load back). libFuzzer records the input as a crash.
[[noreturn]] void invariant_failed(const std::string& what);

/// compare as the CLI runs it, both ways: against the Gaussian references, and calibrated by the
/// referee (the model's simulated world) with a few replicates, so the simulation of every
/// fuzzed suite's runs is exercised too.
void compare_both_ways(const Suite& suite);

/// What an importer wrote must load back as a suite and compare, as in the CLI (order 2 only
/// within its piece limit): writes `files` under a scratch directory and checks that, else
/// invariant_failed naming `importer`.
void check_imported_suite(const std::vector<ImportedFile>& files, const std::string& importer);

}  // namespace odomcov::fuzz

/// Every target: bad input must end in odomcov::InputError; any other exception escapes and
/// libFuzzer reports it as a crash ("uncaught exception").
#define ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE(body) \
  try {                                          \
    body;                                        \
  } catch (const odomcov::InputError&) {         \
  }
