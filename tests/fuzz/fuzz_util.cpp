#include "fuzz_util.hpp"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <regex>

#include "odomcov/measurement/comparison.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/suite_io.hpp"

namespace odomcov::fuzz {
namespace {

namespace fs = std::filesystem;

fs::path fresh(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() /
                       ("odomcov-fuzz-" + std::to_string(::getpid())) / name;
  std::error_code ec;
  fs::remove_all(dir, ec);
  fs::create_directories(dir);
  return dir;
}

bool safe_name(const std::string& name) {
  static const std::regex pattern("[A-Za-z0-9_-][A-Za-z0-9_.-]{0,63}");
  return std::regex_match(name, pattern);
}

}  // namespace

void write_text(const fs::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
}

fs::path scratch_dir(const std::string& name) { return fresh(name); }

fs::path unpack(const std::uint8_t* data, std::size_t size, const std::string& main_name) {
  const fs::path dir = fresh("in");
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::string name = main_name, body;
  std::size_t pos = 0;
  auto flush = [&] {
    if (safe_name(name)) write_text(dir / name, body);
    body.clear();
  };
  while (pos <= text.size()) {
    std::size_t end = text.find('\n', pos);
    const bool last = end == std::string::npos;
    if (last) end = text.size();
    const std::string line = text.substr(pos, end - pos);
    if (line.rfind("#@ ", 0) == 0) {
      flush();
      name = line.substr(3);
    } else {
      body += line;
      if (!last) body += '\n';
    }
    if (last) break;
    pos = end + 1;
  }
  flush();
  return dir;
}

void invariant_failed(const std::string& what) {
  std::fprintf(stderr, "odomcov fuzz invariant failed: %s\n", what.c_str());
  std::abort();
}

void compare_both_ways(const Suite& suite) {
  CalibrationOptions c;
  c.method = CalibrationMethod::gaussian;
  compare(suite, suite_model(suite), 0.01, c);
  c.method = CalibrationMethod::simulation;
  c.max_replicates = 9;
  compare(suite, suite_model(suite), 0.01, c);
}

void check_imported_suite(const std::vector<ImportedFile>& files, const std::string& importer) {
  const fs::path out = scratch_dir("out");
  for (const ImportedFile& f : files) {
    fs::create_directories((out / f.path).parent_path());
    write_text(out / f.path, f.text);
  }
  try {
    const Suite suite = load_suite((out / "suite.yaml").string());
    // As the CLI: order 2 (the default) beyond its piece limit is refused, not computed.
    if (second_order_problem(suite, suite_model(suite).order).empty()) {
      compare_both_ways(suite);
    }
  } catch (const InputError& e) {
    invariant_failed(importer + " wrote a suite that does not load: " + e.what());
  }
}

}  // namespace odomcov::fuzz
