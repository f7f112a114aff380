#include "csv.hpp"

#include <cmath>
#include <fstream>

#include "odomcov/error.hpp"

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
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(cell, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != cell.size()) fail(meta->file, line, column, "not a number: '" + cell + "'");
  if (!std::isfinite(value)) fail(meta->file, line, column, "must be finite, got " + cell);
  return value;
}

Table read(const std::string& file, const std::vector<std::string>& columns) {
  std::ifstream in(file);
  if (!in) throw InputError(file, 0, "", "cannot open file");
  auto meta = std::make_shared<Meta>(Meta{file, columns});
  Table table{meta, {}};
  std::string line;
  int number = 0;
  bool header = false;
  while (std::getline(in, line)) {
    ++number;
    if (trim(line).empty()) continue;
    std::vector<std::string> cells = split(line);
    if (!header) {
      if (cells != columns) {
        fail(file, number, "", "expected the header '" + joined(columns) + "', got '" + trim(line) + "'");
      }
      header = true;
      continue;
    }
    if (cells.size() != columns.size()) {
      fail(file, number, "", "expected " + std::to_string(columns.size()) + " cells, got " +
                                 std::to_string(cells.size()));
    }
    table.rows.push_back({meta, number, std::move(cells)});
  }
  if (!header) throw InputError(file, 0, "", "empty file: expected the header '" + joined(columns) + "'");
  if (table.rows.empty()) throw InputError(file, number, "", "no data rows after the header");
  return table;
}

Table read_headerless(const std::string& file, std::size_t min_cells) {
  std::ifstream in(file);
  if (!in) throw InputError(file, 0, "", "cannot open file");
  auto meta = std::make_shared<Meta>(Meta{file, {}});
  Table table{meta, {}};
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
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
