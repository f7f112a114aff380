// The one exception type for bad user input. Its message is a single line
//   FILE:LINE: KEY: what is wrong
// (line and key are left out where unknown), printed by the CLI before it exits with code 2.
#pragma once

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
  /// What is wrong, without the file:line: key prefix.
  const std::string& message() const { return message_; }

 private:
  std::string file_;
  int line_;
  std::string key_;
  std::string message_;
};

}  // namespace odomcov
