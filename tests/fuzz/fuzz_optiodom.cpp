// Fuzz target: one OptiOdom session (sections "#@ S_metadata.csv", "#@ S_run-01.csv", ... with
// S the session name "20000101"), imported; what the importer writes must load back as a suite.
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/io/optiodom.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  namespace fs = std::filesystem;
  const auto in = fuzz::unpack(data, size, "notes.txt");
  // The importer wants TYPE/SESSION directories: move the sections into square/20000101.
  const fs::path session = fuzz::scratch_dir("session") / "square" / "20000101";
  fs::create_directories(session);
  for (const auto& entry : fs::directory_iterator(in)) {
    fs::rename(entry.path(), session / entry.path().filename());
  }
  std::vector<ImportedFile> files;
  try {
    OptiOdomOptions options;
    options.sessions = {session.string()};
    files = import_optiodom(options);
  } catch (const InputError&) {
    return 0;
  }
  fuzz::check_imported_suite(files, "import optiodom");
  return 0;
}
