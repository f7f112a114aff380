#include "io/input_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "odomcov/base/error.hpp"

namespace odomcov {

std::string read_input_file(const std::string& file, std::int64_t max_bytes, const char* kind) {
  struct stat st {};
  if (::stat(file.c_str(), &st) != 0) {
    throw InputError(file, 0, "", std::string("cannot open file (") + std::strerror(errno) + ")");
  }
  if (S_ISDIR(st.st_mode)) throw InputError(file, 0, "", std::string("is a directory, expected a ") + kind);
  if (!S_ISREG(st.st_mode)) {
    throw InputError(file, 0, "", std::string("not a regular file (a device, FIFO or socket), expected a ") + kind);
  }
  auto too_big = [&](std::int64_t size) {
    return InputError(file, 0, "", std::string(kind) + " of " + std::to_string(size) +
                                       " bytes is above the limit of " + std::to_string(max_bytes) +
                                       " bytes");
  };
  if (st.st_size > max_bytes) throw too_big(st.st_size);
  // O_NONBLOCK: should the file have been swapped for a FIFO since stat, open does not wait.
  const int fd = ::open(file.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw InputError(file, 0, "", std::string("cannot open file (") + std::strerror(errno) + ")");
  struct stat opened {};
  if (::fstat(fd, &opened) != 0 || !S_ISREG(opened.st_mode)) {
    ::close(fd);
    throw InputError(file, 0, "", std::string("not a regular file, expected a ") + kind);
  }
  std::string text;
  text.reserve(static_cast<std::size_t>(opened.st_size));
  char buf[1 << 16];
  while (true) {
    const ssize_t got = ::read(fd, buf, sizeof buf);
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) {
      const int err = errno;
      ::close(fd);
      throw InputError(file, 0, "", std::string("cannot read file (") + std::strerror(err) + ")");
    }
    if (got == 0) break;
    text.append(buf, static_cast<std::size_t>(got));
    if (static_cast<std::int64_t>(text.size()) > max_bytes) {  // grew while being read
      ::close(fd);
      throw too_big(static_cast<std::int64_t>(text.size()));
    }
  }
  ::close(fd);
  return text;
}

}  // namespace odomcov
