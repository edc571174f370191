#pragma once
/// A file written under a temporary name in the same folder and renamed to
/// its final name only by commit(): a command never leaves a half-written
/// file at a final name. Without commit() the temporary file is removed, also
/// when the process is ended by SIGINT, SIGTERM or SIGHUP (see
/// install_signal_cleanup).
///
/// A ResultSet gathers the files of one command's result in a staging folder
/// inside OUT and moves them to OUT together, then writes OUT/manifest.json
/// last: a folder whose manifest is missing is not a complete result set.
#include <sys/types.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace twin::io {

/// Installs handlers for SIGINT, SIGTERM and SIGHUP that stop a running child
/// (gnuplot), remove every registered temporary path and then end the process
/// by the same signal. Called once by main().
void install_signal_cleanup();

/// A path removed by the signal handler while this object lives (the owner
/// removes it in the ordinary way). Files are unlinked before folders are
/// removed, so a registered folder goes once its registered files are gone.
class TempPathGuard {
 public:
  TempPathGuard() = default;
  explicit TempPathGuard(const std::filesystem::path& path);
  ~TempPathGuard();
  TempPathGuard(TempPathGuard&& other) noexcept;
  TempPathGuard& operator=(TempPathGuard&& other) noexcept;
  TempPathGuard(const TempPathGuard&) = delete;
  TempPathGuard& operator=(const TempPathGuard&) = delete;

 private:
  int slot_{-1};
};

/// A child process the signal handler kills (and reaps) before removing the
/// temporary paths, so that it writes nothing after them.
class ChildGuard {
 public:
  explicit ChildGuard(pid_t pid);
  ~ChildGuard();
  ChildGuard(const ChildGuard&) = delete;
  ChildGuard& operator=(const ChildGuard&) = delete;
};

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
  TempPathGuard guard_;
  std::FILE* file_{nullptr};
  bool committed_{false};
};

/// The files of one command's result, staged in OUT/.twin-staging.<pid>/ and
/// moved into OUT by commit(), which then writes OUT/manifest.json (command,
/// and per file its name, size and CRC-32) as the last step. The manifest of
/// an earlier result in OUT is removed before the first file is moved, and
/// files it listed that the new result does not have are removed, so OUT never
/// holds old and new files under one manifest. Without commit() (an error or a
/// signal) the staging folder is removed and OUT is left as it was.
class ResultSet {
 public:
  /// Creates OUT (and parents) and the staging folder; IoError if it cannot.
  ResultSet(std::filesystem::path out_dir, std::string command);
  ~ResultSet();
  ResultSet(const ResultSet&) = delete;
  ResultSet& operator=(const ResultSet&) = delete;

  /// Where to write the file `name` (a plain file name) now: inside the staging folder.
  std::filesystem::path path(const std::string& name);
  /// The staging folder (the working folder of plots).
  const std::filesystem::path& staging_dir() const noexcept { return staging_; }
  const std::filesystem::path& out_dir() const noexcept { return out_; }
  /// Where `name` will be after commit().
  std::filesystem::path final_path(const std::string& name) const { return out_ / name; }
  /// Moves every staged file that exists into OUT and writes the manifest.
  /// Returns the final paths in the order path() was first asked for them.
  std::vector<std::filesystem::path> commit();

 private:
  std::filesystem::path out_;
  std::filesystem::path staging_;
  std::string command_;
  TempPathGuard staging_guard_;
  std::vector<std::string> names_;
  std::vector<TempPathGuard> guards_;
  bool committed_{false};
};

/// Name of the manifest a ResultSet writes last.
inline constexpr const char* kManifestName = "manifest.json";

/// Writes `text` to `path` atomically.
void write_file_atomic(const std::filesystem::path& path, std::string_view text);
/// Opens `path` for reading as read_file does: a regular file only (a FIFO is
/// never waited on), at most `max_bytes` on disk. Returns the descriptor and,
/// in `size_bytes`, the file's size; throws IoError "cannot read PATH: why".
int open_regular_file(const std::filesystem::path& path, std::uintmax_t max_bytes, std::uintmax_t* size_bytes);

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
