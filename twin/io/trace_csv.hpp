#pragma once
/// trace.csv of spec/measured-data.md: one header line of unit-carrying
/// names, one row per sample, increasing time. Readers accept trace.csv and
/// trace.csv.gz.
#include <cstdint>
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

/// Streams rows to disk (memory stays flat however long the run). A path
/// ending in ".gz" is written gzip-compressed (trace.csv.gz, which every
/// reader of traces accepts), compressed as it streams. Numbers are written
/// as printf's "%.10g" would (std::to_chars), "-0" as "0"; a row is formatted
/// into a fixed buffer, with no allocation per row. Rows are handed to a
/// second thread in blocks of kRowsPerBlock, which formats, compresses and
/// writes them while the caller goes on: the caller's cost per row is a copy.
/// An error of that thread (a full disk) is thrown by the next write_row or
/// commit.
class TraceWriter {
 public:
  TraceWriter(const std::filesystem::path& path, std::vector<std::string> names);
  ~TraceWriter();
  TraceWriter(const TraceWriter&) = delete;
  TraceWriter& operator=(const TraceWriter&) = delete;
  void write_row(const double* values, std::size_t n);
  void write_row(const std::vector<double>& values) { write_row(values.data(), values.size()); }
  void commit();
  std::size_t num_columns() const noexcept { return names_.size(); }
  std::uint64_t num_rows() const noexcept { return rows_; }
  static constexpr std::size_t kRowsPerBlock = 2048;
  bool compressed() const noexcept { return deflater_ != nullptr; }

 private:
  struct Deflater;
  struct Pipeline;
  void drain(bool finish);
  void format_rows(const double* values, std::size_t rows);
  void hand_off();
  void work();
  AtomicFile file_;
  std::vector<std::string> names_;
  std::vector<char> buffer_;
  std::size_t used_{0};
  std::uint64_t rows_{0};
  std::unique_ptr<Deflater> deflater_;
  std::vector<double> block_;       ///< rows the caller is filling
  std::size_t block_rows_{0};
  std::unique_ptr<Pipeline> pipeline_;
};

/// How `twin run` writes its trace: plain CSV (trace.csv) or the same
/// gzip-compressed (trace.csv.gz).
enum class TraceFormat { kCsv, kCsvGz };
/// "csv" or "csv.gz"; ConfigError naming the option otherwise.
TraceFormat parse_trace_format(std::string_view text);
/// Decompresses a gzip file to `plain` (written atomically), streaming in
/// fixed chunks: memory stays flat however large the file.
void gunzip_file(const std::filesystem::path& gz, const std::filesystem::path& plain);
/// "trace.csv" or "trace.csv.gz".
const char* trace_file_name(TraceFormat format) noexcept;

}  // namespace twin::io
