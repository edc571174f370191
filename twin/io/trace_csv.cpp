#include "twin/io/trace_csv.hpp"

#include <charconv>
#include <cmath>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::io {

const std::vector<double>* TraceTable::find(std::string_view name) const noexcept {
  for (std::size_t c = 0; c < names.size(); ++c)
    if (names[c] == name) return &columns[c];
  return nullptr;
}

const std::vector<double>& TraceTable::at(std::string_view name) const {
  if (const auto* c = find(name)) return *c;
  throw IoError(fmt::format("{}: missing column {}", source, name));
}

namespace {
std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.back() == '\r' || s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  return s;
}
}  // namespace

TraceTable read_trace_csv(const std::filesystem::path& path) {
  const std::string text = read_file(path);
  TraceTable t;
  t.source = path.string();
  std::size_t pos = 0;
  std::size_t line_no = 0;
  auto next_line = [&](std::string_view& line) {
    if (pos >= text.size()) return false;
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    line = std::string_view(text).substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    return true;
  };
  std::string_view line;
  if (!next_line(line) || trim(line).empty()) throw IoError(fmt::format("{}: empty file, no header line", t.source));
  {
    std::string_view h = trim(line);
    if (!h.empty() && static_cast<unsigned char>(h[0]) == 0xEF) h.remove_prefix(std::min<std::size_t>(3, h.size()));
    std::size_t start = 0;
    while (true) {
      const std::size_t comma = h.find(',', start);
      const std::string_view name = trim(h.substr(start, comma == std::string_view::npos ? h.npos : comma - start));
      if (name.empty()) throw IoError(fmt::format("{}:1: empty column name in the header", t.source));
      for (const auto& n : t.names)
        if (n == name) throw IoError(fmt::format("{}:1: column {} appears twice", t.source, name));
      t.names.emplace_back(name);
      if (comma == std::string_view::npos) break;
      start = comma + 1;
    }
  }
  const std::size_t nc = t.names.size();
  t.columns.assign(nc, {});
  const std::size_t estimate = text.size() / (nc * 8 + 1);
  for (auto& c : t.columns) c.reserve(estimate);
  while (next_line(line)) {
    const std::string_view l = trim(line);
    if (l.empty()) continue;
    std::size_t start = 0;
    for (std::size_t c = 0; c < nc; ++c) {
      const std::size_t comma = l.find(',', start);
      if (comma == std::string_view::npos && c + 1 < nc)
        throw IoError(fmt::format("{}:{}: {} fields, the header has {}", t.source, line_no, c + 1, nc));
      if (comma != std::string_view::npos && c + 1 == nc)
        throw IoError(fmt::format("{}:{}: more fields than the {} of the header", t.source, line_no, nc));
      const std::string_view f = trim(l.substr(start, comma == std::string_view::npos ? l.npos : comma - start));
      double v = 0.0;
      const auto [p, ec] = std::from_chars(f.data(), f.data() + f.size(), v);
      if (f.empty() || ec != std::errc() || p != f.data() + f.size())
        throw IoError(fmt::format("{}:{}: column {}: '{}' is not a number", t.source, line_no, t.names[c], f));
      if (!std::isfinite(v))
        throw IoError(fmt::format("{}:{}: column {}: {} is not finite", t.source, line_no, t.names[c], f));
      t.columns[c].push_back(v);
      start = comma + 1;
    }
  }
  if (t.num_rows() == 0) throw IoError(fmt::format("{}: no data rows", t.source));
  const auto* time = t.find("t_s");
  if (time == nullptr) throw IoError(fmt::format("{}: missing column t_s", t.source));
  for (std::size_t r = 1; r < time->size(); ++r)
    if (!((*time)[r] > (*time)[r - 1]))
      throw IoError(fmt::format("{}: t_s is not increasing at data row {} (t = {} s after {} s)", t.source, r + 1,
                                (*time)[r], (*time)[r - 1]));
  return t;
}

TraceWriter::TraceWriter(const std::filesystem::path& path, std::vector<std::string> names)
    : file_(path), names_(std::move(names)) {
  std::string header;
  for (std::size_t i = 0; i < names_.size(); ++i) {
    if (i) header += ',';
    header += names_[i];
  }
  header += '\n';
  file_.write(header);
  buffer_.reserve(1 << 16);
}

void TraceWriter::write_row(const double* values, std::size_t n) {
  if (n != names_.size())
    throw IoError(fmt::format("{}: row of {} values for {} columns", file_.final_path().string(), n, names_.size()));
  for (std::size_t i = 0; i < n; ++i) {
    if (i) buffer_ += ',';
    const double v = values[i] == 0.0 ? 0.0 : values[i];  // no "-0"
    if (!std::isfinite(v))
      throw ModelError(fmt::format("{}: non-finite value in column {}", file_.final_path().string(), names_[i]));
    fmt::format_to(std::back_inserter(buffer_), "{:.10g}", v);
  }
  buffer_ += '\n';
  if (buffer_.size() > (1 << 15)) {
    file_.write(buffer_);
    buffer_.clear();
  }
}

void TraceWriter::commit() {
  file_.write(buffer_);
  buffer_.clear();
  file_.commit();
}

}  // namespace twin::io
