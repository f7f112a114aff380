// Strict reading of the small CSV files of measurement suites and recordings: a header that must
// match, comma-separated cells, and errors that name file, line and column.
#pragma once

#include <memory>
#include <string>
#include <vector>

namespace odomcov::csv {

[[noreturn]] void fail(const std::string& file, int line, const std::string& column,
                       const std::string& what);

struct Meta {
  std::string file;
  std::vector<std::string> columns;
};

struct Row {
  std::shared_ptr<const Meta> meta;
  int line = 0;  // 1-based line in the file
  std::vector<std::string> cells;

  /// A finite number (InputError naming the column otherwise).
  double number(std::size_t i) const;
  const std::string& text(std::size_t i) const { return cells[i]; }
  bool empty(std::size_t i) const { return cells[i].empty(); }
};

struct Table {
  std::shared_ptr<const Meta> meta;
  std::vector<Row> rows;
};

/// Reads `file`: the header must be exactly `columns` (spaces around names ignored), every row
/// must have that many cells, and there must be at least one row. Blank lines are skipped.
Table read(const std::string& file, const std::vector<std::string>& columns);
/// The same with an optional last column: the header is `columns`, or `columns` then
/// `optional` (the table's meta lists the columns the file has).
Table read(const std::string& file, const std::vector<std::string>& columns, const std::string& optional);
/// The same with any of `headers` (the first when the file has none; the table's meta lists the
/// columns the file has).
Table read_any(const std::string& file, const std::vector<std::vector<std::string>>& headers);

/// Reads a headerless numeric CSV (recordings): every row must have `min_cells` cells or more.
Table read_headerless(const std::string& file, std::size_t min_cells);

}  // namespace odomcov::csv
