#include "twin/io/trace_csv.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <algorithm>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>

#include <fmt/format.h>
#include <zlib.h>

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

namespace {

// The lines of a trace file, read and (for a .gz, or any gzip data) inflated
// in fixed chunks and handed out as views: no copy of the whole text is held,
// so a gzip'd trace is read at the speed of a plain one. The checks and
// messages are read_file's: a regular file only (a FIFO is never waited on),
// at most kMaxReadBytes compressed and uncompressed.
class LineReader {
 public:
  explicit LineReader(const std::filesystem::path& path) : path_(path) {
    const int fd = open_regular_file(path, kMaxReadBytes, &file_bytes_);
    gz_ = gzdopen(fd, "rb");
    if (gz_ == nullptr) {
      ::close(fd);
      throw fail("cannot open");
    }
    gzbuffer(gz_, 1u << 17);
    buf_.resize(std::size_t{1} << 20);
  }
  ~LineReader() {
    if (gz_ != nullptr) gzclose(gz_);
  }
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  std::uintmax_t file_bytes() const noexcept { return file_bytes_; }
  bool compressed() const noexcept { return gzdirect(gz_) == 0; }

  /// The next line without its '\n'; false at the end.
  bool next(std::string_view& line) {
    for (;;) {
      const char* b = buf_.data() + begin_;
      const char* nl = static_cast<const char*>(std::memchr(b, '\n', end_ - begin_));
      if (nl != nullptr) {
        line = std::string_view(b, static_cast<std::size_t>(nl - b));
        begin_ += line.size() + 1;
        return true;
      }
      if (eof_) {
        if (begin_ == end_) return false;
        line = std::string_view(b, end_ - begin_);
        begin_ = end_;
        return true;
      }
      fill();
    }
  }

 private:
  IoError fail(const std::string& why) const { return IoError(fmt::format("cannot read {}: {}", path_.string(), why)); }
  std::string limit() const {
    return fmt::format("the limit is {:.0f} MB", static_cast<double>(kMaxReadBytes) / 1048576.0);
  }
  void fill() {
    if (begin_ > 0) {  // keep the unfinished line at the front
      std::memmove(buf_.data(), buf_.data() + begin_, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
    }
    if (end_ == buf_.size()) buf_.resize(buf_.size() * 2);  // a line longer than the buffer
    const int n = gzread(gz_, buf_.data() + end_, static_cast<unsigned>(std::min<std::size_t>(buf_.size() - end_, 1u << 30)));
    if (n < 0) {
      int err = 0;
      throw fail(gzerror(gz_, &err));
    }
    if (n == 0) {
      eof_ = true;
      return;
    }
    end_ += static_cast<std::size_t>(n);
    total_ += static_cast<std::uintmax_t>(n);
    if (total_ > kMaxReadBytes) throw fail(fmt::format("more than {} bytes once uncompressed, {}", kMaxReadBytes, limit()));
  }

  std::filesystem::path path_;
  gzFile gz_{nullptr};
  std::vector<char> buf_;
  std::size_t begin_{0};
  std::size_t end_{0};
  std::uintmax_t total_{0};
  std::uintmax_t file_bytes_{0};
  bool eof_{false};
};

}  // namespace

TraceTable read_trace_csv(const std::filesystem::path& path) {
  LineReader reader(path);
  TraceTable t;
  t.source = path.string();
  std::size_t line_no = 0;
  auto next_line = [&](std::string_view& line) {
    if (!reader.next(line)) return false;
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
  // Rows expected, for one allocation per column: about 4x the size once a gzip'd trace is inflated.
  const std::uintmax_t text_bytes = std::min<std::uintmax_t>(reader.file_bytes() * (reader.compressed() ? 4 : 1),
                                                             kMaxReadBytes);
  const std::size_t estimate = static_cast<std::size_t>(text_bytes / (nc * 8 + 1));
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

namespace {
// Room a row of n fields may take: "%.10g" of a finite double is at most 17
// characters ("-1.234567891e-308"), plus the comma or newline.
constexpr std::size_t kMaxFieldChars = 24;
constexpr std::size_t kBufferBytes = std::size_t{1} << 18;
// zlib level 1: the trace is written as fast as the simulation makes it, and
// level 6 saves little more on numeric text (docs/performance.md).
constexpr int kGzipLevel = 1;
}  // namespace

struct TraceWriter::Deflater {
  z_stream stream{};
  std::vector<unsigned char> out;
  bool initialised{false};
  ~Deflater() {
    if (initialised) deflateEnd(&stream);
  }
};

struct TraceWriter::Pipeline {
  std::mutex mutex;
  std::condition_variable cv;
  std::vector<double> pending;  ///< the block the formatting thread owns while has_pending
  std::size_t pending_rows{0};
  bool has_pending{false};
  bool stop{false};
  std::exception_ptr error;
  std::thread thread;
};

TraceWriter::TraceWriter(const std::filesystem::path& path, std::vector<std::string> names)
    : file_(path), names_(std::move(names)) {
  if (path.extension() == ".gz") {
    deflater_ = std::make_unique<Deflater>();
    // windowBits 15 + 16: a gzip header and trailer around the deflate stream.
    if (deflateInit2(&deflater_->stream, kGzipLevel, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
      throw IoError(fmt::format("{}: cannot start the gzip stream", path.string()));
    deflater_->initialised = true;
    deflater_->out.resize(kBufferBytes);
  }
  std::size_t header_chars = 1;
  for (const auto& n : names_) header_chars += n.size() + 1;
  buffer_.resize(std::max(kBufferBytes, 2 * (header_chars + names_.size() * kMaxFieldChars)));
  for (std::size_t i = 0; i < names_.size(); ++i) {
    if (i) buffer_[used_++] = ',';
    std::copy(names_[i].begin(), names_[i].end(), buffer_.begin() + static_cast<std::ptrdiff_t>(used_));
    used_ += names_[i].size();
  }
  buffer_[used_++] = '\n';
  block_.resize(kRowsPerBlock * std::max<std::size_t>(1, names_.size()));
  pipeline_ = std::make_unique<Pipeline>();
  pipeline_->pending.resize(block_.size());
  pipeline_->thread = std::thread([this] { work(); });
}

TraceWriter::~TraceWriter() {
  if (pipeline_ && pipeline_->thread.joinable()) {
    {
      std::lock_guard lock(pipeline_->mutex);
      pipeline_->stop = true;
      pipeline_->cv.notify_all();
    }
    pipeline_->thread.join();
  }
}

void TraceWriter::drain(bool finish) {
  if (!deflater_) {
    file_.write(std::string_view(buffer_.data(), used_));
    used_ = 0;
    return;
  }
  z_stream& z = deflater_->stream;
  z.next_in = reinterpret_cast<Bytef*>(buffer_.data());
  z.avail_in = static_cast<uInt>(used_);
  const int flush = finish ? Z_FINISH : Z_NO_FLUSH;
  int rc = Z_OK;
  do {
    z.next_out = deflater_->out.data();
    z.avail_out = static_cast<uInt>(deflater_->out.size());
    rc = deflate(&z, flush);
    if (rc == Z_STREAM_ERROR)
      throw IoError(fmt::format("cannot write {}: gzip stream error", file_.final_path().string()));
    const std::size_t have = deflater_->out.size() - z.avail_out;
    file_.write(std::string_view(reinterpret_cast<const char*>(deflater_->out.data()), have));
  } while (z.avail_out == 0 || (finish && rc != Z_STREAM_END));
  used_ = 0;
}

void TraceWriter::work() {
  Pipeline& q = *pipeline_;
  for (;;) {
    std::unique_lock lock(q.mutex);
    q.cv.wait(lock, [&] { return q.has_pending || q.stop; });
    if (!q.has_pending) return;
    lock.unlock();
    try {
      format_rows(q.pending.data(), q.pending_rows);
    } catch (...) {
      lock.lock();
      q.error = std::current_exception();
      q.has_pending = false;
      q.cv.notify_all();
      return;
    }
    lock.lock();
    q.has_pending = false;
    q.cv.notify_all();
  }
}

void TraceWriter::hand_off() {
  Pipeline& q = *pipeline_;
  std::unique_lock lock(q.mutex);
  q.cv.wait(lock, [&] { return !q.has_pending; });
  if (q.error) std::rethrow_exception(q.error);
  std::swap(block_, q.pending);
  q.pending_rows = block_rows_;
  q.has_pending = true;
  block_rows_ = 0;
  q.cv.notify_all();
}

void TraceWriter::format_rows(const double* values, std::size_t rows) {
  const std::size_t n = names_.size();
  for (std::size_t row = 0; row < rows; ++row, values += n) {
    if (used_ + n * kMaxFieldChars + 1 > buffer_.size()) drain(false);
    char* p = buffer_.data() + used_;
    char* const end = buffer_.data() + buffer_.size();
    for (std::size_t i = 0; i < n; ++i) {
      p = std::to_chars(p, end, values[i], std::chars_format::general, 10).ptr;
      *p++ = i + 1 < n ? ',' : '\n';
    }
    used_ = static_cast<std::size_t>(p - buffer_.data());
  }
}

void TraceWriter::write_row(const double* values, std::size_t n) {
  if (n != names_.size())
    throw IoError(fmt::format("{}: row of {} values for {} columns", file_.final_path().string(), n, names_.size()));
  double* out = block_.data() + block_rows_ * n;
  for (std::size_t i = 0; i < n; ++i) {
    const double v = values[i] == 0.0 ? 0.0 : values[i];  // no "-0"
    if (!std::isfinite(v))
      throw ModelError(fmt::format("{}: non-finite value in column {}", file_.final_path().string(), names_[i]));
    out[i] = v;
  }
  ++rows_;
  if (++block_rows_ == kRowsPerBlock) hand_off();
}

void TraceWriter::commit() {
  if (!pipeline_->thread.joinable()) throw IoError(fmt::format("{}: committed twice", file_.final_path().string()));
  if (block_rows_ > 0) hand_off();
  {
    std::lock_guard lock(pipeline_->mutex);
    pipeline_->stop = true;
    pipeline_->cv.notify_all();
  }
  pipeline_->thread.join();
  if (pipeline_->error) std::rethrow_exception(pipeline_->error);
  drain(true);
  file_.commit();
}

TraceFormat parse_trace_format(std::string_view text) {
  if (text == "csv") return TraceFormat::kCsv;
  if (text == "csv.gz") return TraceFormat::kCsvGz;
  throw ConfigError(fmt::format("--trace-format: '{}' is not a trace format (csv or csv.gz)", text));
}

void gunzip_file(const std::filesystem::path& gz, const std::filesystem::path& plain) {
  gzFile in = gzopen(gz.c_str(), "rb");
  if (in == nullptr) throw IoError(fmt::format("cannot read {}: cannot open", gz.string()));
  AtomicFile out(plain);
  std::vector<char> buf(kBufferBytes);
  for (;;) {
    const int n = gzread(in, buf.data(), static_cast<unsigned>(buf.size()));
    if (n < 0) {
      int err = 0;
      const std::string msg = gzerror(in, &err);
      gzclose(in);
      throw IoError(fmt::format("cannot read {}: {}", gz.string(), msg));
    }
    if (n == 0) break;
    out.write(std::string_view(buf.data(), static_cast<std::size_t>(n)));
  }
  gzclose(in);
  out.commit();
}

const char* trace_file_name(TraceFormat format) noexcept {
  return format == TraceFormat::kCsvGz ? "trace.csv.gz" : "trace.csv";
}

}  // namespace twin::io
