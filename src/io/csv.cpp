#include "io/csv.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "io/input_file.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/closed_form/limits.hpp"

namespace odomcov::csv {
namespace {

std::string trim(const std::string& s) {
  const auto begin = s.find_first_not_of(" \t\r");
  if (begin == std::string::npos) return "";
  const auto end = s.find_last_not_of(" \t\r");
  return s.substr(begin, end - begin + 1);
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> cells;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    cells.push_back(trim(line.substr(start, comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return cells;
}

/// The file's lines: a UTF-8 byte-order mark is dropped, and CRLF ends lines like LF (the
/// cells are trimmed of '\r' as well).
std::vector<std::string> lines_of(const std::string& file) {
  std::string text = read_input_file(file, kMaxCsvBytes, "CSV file");
  if (text.rfind("\xEF\xBB\xBF", 0) == 0) text.erase(0, 3);
  std::vector<std::string> lines;
  std::size_t start = 0;
  while (start < text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    lines.push_back(text.substr(start, end - start));
    start = end + 1;
  }
  return lines;
}

std::string joined(const std::vector<std::string>& columns) {
  std::string text;
  for (const auto& c : columns) text += (text.empty() ? "" : ",") + c;
  return text;
}

}  // namespace

void fail(const std::string& file, int line, const std::string& column, const std::string& what) {
  throw InputError(file, line, column.empty() ? "" : "column '" + column + "'", what);
}

double Row::number(std::size_t i) const {
  const std::string column = i < meta->columns.size() ? meta->columns[i] : std::to_string(i + 1);
  const std::string& cell = cells.at(i);
  if (cell.empty()) fail(meta->file, line, column, "empty cell");
  // Decimal numbers only: strtod also reads "nan", "inf", "infinity" and hex floats, which
  // are refused here, and a value that overflows a double ("1e400") is not finite.
  if (cell.find_first_not_of("0123456789+-.eE") != std::string::npos) {
    const bool non_finite = cell.find_first_of("nNiI") != std::string::npos &&
                            cell.find_first_not_of("+-nNaAiIfFtTyY") == std::string::npos;
    fail(meta->file, line, column,
         non_finite ? "must be finite, got " + quote(cell) : "not a number: " + quote(cell));
  }
  errno = 0;
  char* end = nullptr;
  const double value = std::strtod(cell.c_str(), &end);
  if (end != cell.c_str() + cell.size()) fail(meta->file, line, column, "not a number: " + quote(cell));
  if (!std::isfinite(value) || (errno == ERANGE && std::abs(value) > 1.0)) {
    fail(meta->file, line, column, "must be finite, got " + quote(cell));
  }
  return value;
}

Table read(const std::string& file, const std::vector<std::string>& columns) {
  return read_any(file, {columns});
}

Table read(const std::string& file, const std::vector<std::string>& columns, const std::string& optional) {
  std::vector<std::string> with_optional = columns;
  with_optional.push_back(optional);
  return read_any(file, {columns, with_optional});
}

Table read_any(const std::string& file, const std::vector<std::vector<std::string>>& headers) {
  auto meta = std::make_shared<Meta>(Meta{file, headers.front()});
  Table table{meta, {}};
  int number = 0;
  bool header = false;
  auto expected = [&headers] {
    std::string out;
    for (std::size_t i = 0; i < headers.size(); ++i) {
      out += (i == 0 ? "'" : i + 1 == headers.size() ? " or '" : ", '") + joined(headers[i]) + "'";
    }
    return out;
  };
  for (const std::string& line : lines_of(file)) {
    ++number;
    if (trim(line).empty()) continue;
    std::vector<std::string> cells = split(line);
    if (!header) {
      const auto match = std::find(headers.begin(), headers.end(), cells);
      if (match == headers.end()) fail(file, number, "", "expected the header " + expected() + ", got " + quote(trim(line)));
      meta->columns = *match;
      header = true;
      continue;
    }
    if (cells.size() != meta->columns.size()) {
      fail(file, number, "", "expected " + std::to_string(meta->columns.size()) + " cells, got " +
                                 std::to_string(cells.size()));
    }
    table.rows.push_back({meta, number, std::move(cells)});
  }
  if (!header) throw InputError(file, 0, "", "empty file: expected the header " + expected());
  if (table.rows.empty()) throw InputError(file, number, "", "no data rows after the header");
  return table;
}

Table read_headerless(const std::string& file, std::size_t min_cells) {
  auto meta = std::make_shared<Meta>(Meta{file, {}});
  Table table{meta, {}};
  int number = 0;
  for (const std::string& line : lines_of(file)) {
    ++number;
    if (trim(line).empty()) continue;
    std::vector<std::string> cells = split(line);
    if (cells.size() < min_cells) {
      fail(file, number, "", "expected at least " + std::to_string(min_cells) + " cells, got " +
                                 std::to_string(cells.size()));
    }
    table.rows.push_back({meta, number, std::move(cells)});
  }
  if (table.rows.empty()) throw InputError(file, 0, "", "empty file");
  return table;
}

}  // namespace odomcov::csv
