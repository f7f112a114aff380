// Fuzz target: a measurement suite with its CSVs and logs (sections "#@ NAME.csv"), then
// `compare` with the suite's own model (the residuals, whitening and every test).
#include <cstdint>

#include "fuzz_util.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/io/suite_io.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "suite.yaml");
  ODOMCOV_FUZZ_INPUT_ERRORS_ARE_FINE({
    const Suite suite = load_suite((dir / "suite.yaml").string());
    std::size_t runs = 0;
    for (const SuiteExperiment& ex : suite.experiments) {
      runs += ex.runs.size();
      for (const SuiteRun& r : ex.runs) runs += r.pieces.size();
    }
    if (runs <= 50'000 && second_order_problem(suite, suite_model(suite).order).empty()) {
      fuzz::compare_both_ways(suite);  // as the CLI: order 2 within its limit
    }
  });
  return 0;
}
