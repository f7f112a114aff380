// The one exception type for bad user input. Its message is a single line
//   FILE:LINE: KEY: what is wrong
// (line and key are left out where unknown), printed by the CLI before it exits with code 2.
// The line is made safe to print: control characters (newline, NUL, ...) are escaped, and
// over-long parts are cut with their size, so a hostile value cannot spread over several lines
// or flood the terminal (docs/bad-input.md).
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>

namespace odomcov {

class InputError : public std::runtime_error {
 public:
  /// `line` is 1-based; 0 means unknown. `key` is the dotted key path, empty if none.
  InputError(std::string file, int line, std::string key, const std::string& what);

  const std::string& file() const { return file_; }
  int line() const { return line_; }
  const std::string& key() const { return key_; }
  /// What is wrong, without the file:line: key prefix (already made one-line).
  const std::string& message() const { return message_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
  std::string message_;
};

/// Longest user value quoted in a message, and longest file, key or message part, in bytes.
inline constexpr std::size_t kMaxQuotedBytes = 100;
inline constexpr std::size_t kMaxMessagePartBytes = 400;

/// `text` on one line: control characters escaped (\n, \t, \0, \xNN), and when longer than
/// `max_bytes` cut at a UTF-8 character boundary with "... (N bytes)".
std::string one_line(const std::string& text, std::size_t max_bytes = kMaxMessagePartBytes);

/// A user value for a message: one_line(value, kMaxQuotedBytes) in single quotes.
std::string quote(const std::string& value);

}  // namespace odomcov
