#pragma once
/// A file written under a temporary name in the same folder and renamed to
/// its final name only by commit(): a command never leaves a half-written
/// file at a final name. Without commit() the temporary file is removed.
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>

namespace twin::io {

class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path final_path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  void write(std::string_view text);
  std::FILE* handle() noexcept { return file_; }
  /// Flushes, closes and renames; throws IoError on any failure.
  void commit();
  const std::filesystem::path& final_path() const noexcept { return final_; }
  const std::filesystem::path& temp_path() const noexcept { return temp_; }

 private:
  std::filesystem::path final_;
  std::filesystem::path temp_;
  std::FILE* file_{nullptr};
  bool committed_{false};
};

/// Writes `text` to `path` atomically.
void write_file_atomic(const std::filesystem::path& path, std::string_view text);
/// Largest file read_file reads by default (after gunzipping).
inline constexpr std::uintmax_t kMaxReadBytes = std::uintmax_t{1} << 30;
/// Reads a whole regular file (transparently gunzipping a .gz) of at most
/// max_bytes (compressed and uncompressed); IoError "cannot read PATH: ..."
/// if it cannot: no such file, is a directory, not a regular file (a FIFO,
/// device or socket, which are never opened for reading), too large.
std::string read_file(const std::filesystem::path& path, std::uintmax_t max_bytes = kMaxReadBytes);
/// Creates the folder (and parents) or throws IoError.
void ensure_directory(const std::filesystem::path& dir);

}  // namespace twin::io
