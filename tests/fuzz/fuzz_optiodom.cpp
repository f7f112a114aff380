// Fuzz target: one OptiOdom session (sections "#@ S_metadata.csv", "#@ S_run-01.csv", ... with
// S the session name "20000101"), imported; what the importer writes must load back as a suite.
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/comparison.hpp"
#include "odomcov/error.hpp"
#include "odomcov/optiodom.hpp"

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
  const fs::path out = fuzz::scratch_dir("out");
  for (const ImportedFile& f : files) {
    fs::create_directories((out / f.path).parent_path());
    fuzz::write_text(out / f.path, f.text);
  }
  try {
    const Suite suite = load_suite((out / "suite.yaml").string());
    // As the CLI: order 2 (the default) beyond its piece limit is refused, not computed.
    if (second_order_problem(suite, suite_model(suite).order).empty()) {
      compare(suite, suite_model(suite), 0.01);
    }
  } catch (const InputError& e) {
    fuzz::invariant_failed(std::string("import wrote a suite that does not load: ") + e.what());
  }
  return 0;
}
