#include "twin/io/atomic_file.hpp"

#include <cerrno>
#include <cstring>
#include <system_error>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "twin/core/error.hpp"

namespace twin::io {

AtomicFile::AtomicFile(std::filesystem::path final_path) : final_(std::move(final_path)) {
  temp_ = final_;
  temp_ += fmt::format(".tmp{}", static_cast<long>(::getpid()));
  file_ = std::fopen(temp_.c_str(), "wb");
  if (file_ == nullptr)
    throw IoError(fmt::format("cannot write {}: {}", final_.string(), std::strerror(errno)));
  static_cast<void>(std::setvbuf(file_, nullptr, _IOFBF, 1 << 20));
}

AtomicFile::~AtomicFile() {
  if (file_ != nullptr) std::fclose(file_);
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicFile::write(std::string_view text) {
  if (file_ == nullptr) throw IoError(fmt::format("{}: write after close", final_.string()));
  if (std::fwrite(text.data(), 1, text.size(), file_) != text.size())
    throw IoError(fmt::format("cannot write {}: {}", final_.string(), std::strerror(errno)));
}

void AtomicFile::commit() {
  if (file_ == nullptr) throw IoError(fmt::format("{}: committed twice", final_.string()));
  const bool ok = std::fflush(file_) == 0 && std::ferror(file_) == 0;
  const int rc = std::fclose(file_);
  file_ = nullptr;
  if (!ok || rc != 0) throw IoError(fmt::format("cannot write {}: {}", final_.string(), std::strerror(errno)));
  std::error_code ec;
  std::filesystem::rename(temp_, final_, ec);
  if (ec) throw IoError(fmt::format("cannot rename {} to {}: {}", temp_.string(), final_.string(), ec.message()));
  committed_ = true;
}

void write_file_atomic(const std::filesystem::path& path, std::string_view text) {
  AtomicFile f(path);
  f.write(text);
  f.commit();
}

std::string read_file(const std::filesystem::path& path, std::uintmax_t max_bytes) {
  auto fail = [&](const std::string& why) {
    return IoError(fmt::format("cannot read {}: {}", path.string(), why));
  };
  // O_NONBLOCK: opening a FIFO must not wait for a writer; it is refused below.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw fail(errno == ENOENT ? std::string("no such file") : std::string(std::strerror(errno)));
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int e = errno;
    ::close(fd);
    throw fail(std::strerror(e));
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    throw fail(S_ISDIR(st.st_mode) ? "is a directory" : "not a regular file (a FIFO, device or socket)");
  }
  const std::string limit = fmt::format("the limit is {:.0f} MB", static_cast<double>(max_bytes) / 1048576.0);
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes) {
    ::close(fd);
    throw fail(fmt::format("{} bytes, {}", static_cast<long long>(st.st_size), limit));
  }
  gzFile gz = gzdopen(fd, "rb");
  if (gz == nullptr) {
    ::close(fd);
    throw fail("cannot open");
  }
  std::string out;
  char buf[1 << 16];
  for (;;) {
    const int n = gzread(gz, buf, sizeof buf);
    if (n < 0) {
      int err = 0;
      const std::string msg = gzerror(gz, &err);
      gzclose(gz);
      throw fail(msg);
    }
    if (n == 0) break;
    if (out.size() + static_cast<std::size_t>(n) > max_bytes) {
      gzclose(gz);
      throw fail(fmt::format("more than {} bytes once uncompressed, {}", max_bytes, limit));
    }
    out.append(buf, static_cast<std::size_t>(n));
  }
  gzclose(gz);
  return out;
}

void ensure_directory(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir))
    throw IoError(fmt::format("cannot create folder {}: {}", dir.string(), ec ? ec.message() : "not a folder"));
}

}  // namespace twin::io
