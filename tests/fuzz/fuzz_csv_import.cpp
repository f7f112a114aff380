// Fuzz target: the generic log importer (`import csv`, docs/formats.md). The main section is
// run-01.csv; further sections ("#@ run-02.csv", ...) are more runs of the same folder, which is
// one experiment. Wheels in metres (scales 1), B = 0.3 m. What the importer writes must load back
// as a suite and compare; each log is also read as an encoder log for `predict`.
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/io/csv_import.hpp"
#include "odomcov/base/error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  namespace fs = std::filesystem;
  const fs::path in = fuzz::unpack(data, size, "run-01.csv");
  ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE(load_encoder_log((in / "run-01.csv").string()));
  std::vector<ImportedFile> files;
  try {
    CsvImportOptions options;
    options.inputs = {in.string()};
    options.wheelbase_m = 0.3;
    files = import_csv_logs(options);
  } catch (const InputError&) {
    return 0;
  }
  fuzz::check_imported_suite(files, "import csv");
  return 0;
}
