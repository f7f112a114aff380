#include "odomcov/base/error.hpp"

#include <cstdio>

namespace odomcov {
namespace {

std::string format_message(const std::string& file, int line, const std::string& key,
                           const std::string& what) {
  std::string msg = file.empty() ? std::string("<input>") : one_line(file);
  if (line > 0) msg += ":" + std::to_string(line);
  msg += ": ";
  if (!key.empty()) msg += one_line(key) + ": ";
  msg += one_line(what, 2 * kMaxMessagePartBytes);
  return msg;
}

bool continuation(unsigned char c) { return (c & 0xC0) == 0x80; }

}  // namespace

std::string one_line(const std::string& text, std::size_t max_bytes) {
  std::string out;
  std::size_t used = 0;  // bytes of `text` taken
  for (; used < text.size() && out.size() < max_bytes; ++used) {
    const auto c = static_cast<unsigned char>(text[used]);
    if (c >= 0x20 && c != 0x7F) {
      out += static_cast<char>(c);
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c == 0) {
      out += "\\0";
    } else {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02X", c);
      out += buf;
    }
  }
  if (used == text.size()) return out;
  // Cut: back off to a UTF-8 character boundary so the line stays valid text.
  while (!out.empty() && used > 0 && continuation(static_cast<unsigned char>(text[used]))) {
    out.pop_back();
    --used;
  }
  return out + "... (" + std::to_string(text.size()) + " bytes)";
}

std::string quote(const std::string& value) { return "'" + one_line(value, kMaxQuotedBytes) + "'"; }

InputError::InputError(std::string file, int line, std::string key, const std::string& what)
    : std::runtime_error(format_message(file, line, key, what)),
      file_(std::move(file)),
      line_(line),
      key_(std::move(key)),
      message_(one_line(what, 2 * kMaxMessagePartBytes)) {}

}  // namespace odomcov
