#include "odomcov/error.hpp"

namespace odomcov {
namespace {

std::string format_message(const std::string& file, int line, const std::string& key,
                           const std::string& what) {
  std::string msg = file.empty() ? std::string("<input>") : file;
  if (line > 0) msg += ":" + std::to_string(line);
  msg += ": ";
  if (!key.empty()) msg += key + ": ";
  msg += what;
  return msg;
}

}  // namespace

InputError::InputError(std::string file, int line, std::string key, const std::string& what)
    : std::runtime_error(format_message(file, line, key, what)),
      file_(std::move(file)),
      line_(line),
      key_(std::move(key)),
      message_(what) {}

}  // namespace odomcov
