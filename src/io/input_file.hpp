// Reading an input file whole, after checking what it is: a missing file, a directory, a
// device, FIFO or socket, or a file above the size limit is an InputError before any byte is
// read (so `/dev/zero` or a FIFO cannot hang or exhaust memory).
#pragma once

#include <cstdint>
#include <string>

namespace odomcov {

/// The contents of `file`, which must be a regular file of at most `max_bytes`. `kind` names
/// what is expected in messages ("YAML file", "CSV file").
std::string read_input_file(const std::string& file, std::int64_t max_bytes, const char* kind);

}  // namespace odomcov
