#include "fuzz_util.hpp"

#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <regex>

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

}  // namespace odomcov::fuzz
