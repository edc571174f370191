#pragma once
/// trace.csv of spec/measured-data.md: one header line of unit-carrying
/// names, one row per sample, increasing time. Readers accept trace.csv and
/// trace.csv.gz.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "twin/io/atomic_file.hpp"

namespace twin::io {

/// A trace held column by column.
struct TraceTable {
  std::string source;                         ///< file name for messages
  std::vector<std::string> names;
  std::vector<std::vector<double>> columns;   ///< columns[c][row]

  std::size_t num_rows() const noexcept { return columns.empty() ? 0 : columns.front().size(); }
  /// nullptr when absent.
  const std::vector<double>* find(std::string_view name) const noexcept;
  /// IoError "<source>: missing column <name>" when absent.
  const std::vector<double>& at(std::string_view name) const;
};

/// Reads and checks a trace: header present, every row the same number of
/// fields, every field a finite number (NaN and empty fields are errors
/// naming line and column), t_s present and strictly increasing.
TraceTable read_trace_csv(const std::filesystem::path& path);

/// Streams rows to disk (memory stays flat however long the run).
class TraceWriter {
 public:
  TraceWriter(const std::filesystem::path& path, std::vector<std::string> names);
  void write_row(const double* values, std::size_t n);
  void write_row(const std::vector<double>& values) { write_row(values.data(), values.size()); }
  void commit();
  std::size_t num_columns() const noexcept { return names_.size(); }

 private:
  AtomicFile file_;
  std::vector<std::string> names_;
  std::string buffer_;
};

}  // namespace twin::io
