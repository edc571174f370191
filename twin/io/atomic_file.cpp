#include "twin/io/atomic_file.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <system_error>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>
#include <nlohmann/json.hpp>

#include "twin/core/error.hpp"

namespace twin::io {

namespace {

// The state a signal handler reads has to be reachable without arguments: this
// registry is the one process-wide object of the project. Slots hold strdup'ed
// paths; they are taken and released with atomic exchanges, so the handler
// (which may interrupt a registration) sees either a whole path or nothing.
// Only async-signal-safe calls (kill, waitpid, unlink, rmdir, signal, raise)
// are made from the handler.
constexpr std::size_t kTempSlots = 256;
struct CleanupRegistry {
  std::array<std::atomic<char*>, kTempSlots> paths{};
  std::atomic<pid_t> child{0};
};
CleanupRegistry& cleanup_registry() {
  static CleanupRegistry registry;  // constant-initialised: no guard, safe to read from the handler
  return registry;
}

extern "C" void cleanup_and_reraise(int sig) {
  CleanupRegistry& r = cleanup_registry();
  const pid_t child = r.child.exchange(0);
  if (child > 0) {
    ::kill(child, SIGKILL);
    ::waitpid(child, nullptr, 0);
  }
  for (auto& slot : r.paths) {
    const char* p = slot.load();
    if (p != nullptr) ::unlink(p);
  }
  for (auto& slot : r.paths) {
    const char* p = slot.load();
    if (p != nullptr) ::rmdir(p);
  }
  ::signal(sig, SIG_DFL);
  ::raise(sig);
}

int register_temp(const std::filesystem::path& path) {
  char* copy = ::strdup(path.c_str());
  if (copy == nullptr) return -1;
  auto& slots = cleanup_registry().paths;
  for (std::size_t i = 0; i < slots.size(); ++i) {
    char* expected = nullptr;
    if (slots[i].compare_exchange_strong(expected, copy)) return static_cast<int>(i);
  }
  std::free(copy);  // registry full: the path is still removed by its owner, only not on a signal
  return -1;
}

void unregister_temp(int slot) {
  if (slot < 0) return;
  char* p = cleanup_registry().paths[static_cast<std::size_t>(slot)].exchange(nullptr);
  std::free(p);
}

}  // namespace

void install_signal_cleanup() {
  static_cast<void>(cleanup_registry());
  struct sigaction sa {};
  sa.sa_handler = cleanup_and_reraise;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&sa.sa_mask, sig);
  sa.sa_flags = 0;
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(sig, &sa, nullptr);
}

TempPathGuard::TempPathGuard(const std::filesystem::path& path) : slot_(register_temp(path)) {}
TempPathGuard::~TempPathGuard() { unregister_temp(slot_); }
TempPathGuard::TempPathGuard(TempPathGuard&& other) noexcept : slot_(other.slot_) { other.slot_ = -1; }
TempPathGuard& TempPathGuard::operator=(TempPathGuard&& other) noexcept {
  if (this != &other) {
    unregister_temp(slot_);
    slot_ = other.slot_;
    other.slot_ = -1;
  }
  return *this;
}

ChildGuard::ChildGuard(pid_t pid) { cleanup_registry().child.store(pid); }
ChildGuard::~ChildGuard() { cleanup_registry().child.store(0); }

AtomicFile::AtomicFile(std::filesystem::path final_path) : final_(std::move(final_path)) {
  temp_ = final_;
  temp_ += fmt::format(".tmp{}", static_cast<long>(::getpid()));
  guard_ = TempPathGuard(temp_);
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

ResultSet::ResultSet(std::filesystem::path out_dir, std::string command)
    : out_(std::move(out_dir)), command_(std::move(command)) {
  ensure_directory(out_);
  staging_ = out_ / fmt::format(".twin-staging.{}", static_cast<long>(::getpid()));
  staging_guard_ = TempPathGuard(staging_);
  std::error_code ec;
  std::filesystem::remove_all(staging_, ec);  // a leftover of a killed process that had this pid
  ec.clear();
  if (!std::filesystem::create_directory(staging_, ec) || ec)
    throw IoError(fmt::format("cannot create folder {}: {}", staging_.string(),
                              ec ? ec.message() : std::string("it exists")));
}

ResultSet::~ResultSet() {
  if (committed_) return;
  std::error_code ec;
  std::filesystem::remove_all(staging_, ec);
}

std::filesystem::path ResultSet::path(const std::string& name) {
  const std::filesystem::path p(name);
  if (name.empty() || p.has_parent_path() || name == "." || name == ".." || name == kManifestName)
    throw InternalError(fmt::format("result set {}: '{}' is not a plain file name of a result", out_.string(), name));
  if (std::find(names_.begin(), names_.end(), name) == names_.end()) {
    names_.push_back(name);
    guards_.emplace_back(staging_ / name);
  }
  return staging_ / name;
}

namespace {

std::uint32_t file_crc32(const std::filesystem::path& path, std::uintmax_t* bytes) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) throw IoError(fmt::format("cannot read {}: {}", path.string(), std::strerror(errno)));
  uLong crc = crc32(0L, Z_NULL, 0);
  std::uintmax_t total = 0;
  std::vector<unsigned char> buf(1 << 16);
  for (;;) {
    const std::size_t n = std::fread(buf.data(), 1, buf.size(), f);
    if (n == 0) break;
    crc = crc32(crc, buf.data(), static_cast<uInt>(n));
    total += n;
  }
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) throw IoError(fmt::format("cannot read {}", path.string()));
  *bytes = total;
  return static_cast<std::uint32_t>(crc);
}

// File names listed by an earlier manifest (plain names only); none if it is unreadable.
std::vector<std::string> manifest_names(const std::filesystem::path& manifest) {
  std::vector<std::string> names;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(manifest, ec)) return names;
  try {
    const nlohmann::json j = nlohmann::json::parse(read_file(manifest));
    for (const auto& f : j.at("files")) {
      const std::string n = f.at("name").get<std::string>();
      const std::filesystem::path p(n);
      if (!n.empty() && !p.has_parent_path() && n != "." && n != ".." && n != kManifestName) names.push_back(n);
    }
  } catch (const std::exception&) {
    names.clear();  // not a manifest of ours: nothing is removed on its word
  }
  return names;
}

}  // namespace

std::vector<std::filesystem::path> ResultSet::commit() {
  if (committed_) throw InternalError(fmt::format("result set {} committed twice", out_.string()));
  const auto manifest = out_ / kManifestName;
  const std::vector<std::string> old_names = manifest_names(manifest);
  std::error_code ec;
  // From here until the new manifest is written, OUT has none: a folder that holds a
  // mix of an old and a new result is never described by a manifest.
  std::filesystem::remove(manifest, ec);
  if (ec) throw IoError(fmt::format("cannot remove {}: {}", manifest.string(), ec.message()));
  nlohmann::json files = nlohmann::json::array();
  std::vector<std::filesystem::path> written;
  std::vector<std::string> written_names;
  for (const auto& name : names_) {
    const auto staged = staging_ / name;
    if (!std::filesystem::is_regular_file(staged, ec)) continue;
    std::uintmax_t bytes = 0;
    const std::uint32_t crc = file_crc32(staged, &bytes);
    std::filesystem::rename(staged, out_ / name, ec);
    if (ec) throw IoError(fmt::format("cannot move {} to {}: {}", staged.string(), (out_ / name).string(), ec.message()));
    files.push_back({{"name", name}, {"bytes", bytes}, {"crc32", fmt::format("{:08x}", crc)}});
    written.push_back(out_ / name);
    written_names.push_back(name);
  }
  for (const auto& old : old_names) {
    if (std::find(written_names.begin(), written_names.end(), old) != written_names.end()) continue;
    std::filesystem::remove(out_ / old, ec);  // a file of the earlier result that this one does not have
  }
  std::filesystem::remove_all(staging_, ec);
  nlohmann::json m;
  m["command"] = command_;
  m["complete"] = true;
  m["files"] = files;
  write_file_atomic(manifest, m.dump(2) + "\n");
  committed_ = true;
  return written;
}

void write_file_atomic(const std::filesystem::path& path, std::string_view text) {
  AtomicFile f(path);
  f.write(text);
  f.commit();
}

int open_regular_file(const std::filesystem::path& path, std::uintmax_t max_bytes, std::uintmax_t* size_bytes) {
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
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes) {
    ::close(fd);
    throw fail(fmt::format("{} bytes, the limit is {:.0f} MB", static_cast<long long>(st.st_size),
                           static_cast<double>(max_bytes) / 1048576.0));
  }
  if (size_bytes) *size_bytes = static_cast<std::uintmax_t>(st.st_size);
  return fd;
}

std::string read_file(const std::filesystem::path& path, std::uintmax_t max_bytes) {
  auto fail = [&](const std::string& why) {
    return IoError(fmt::format("cannot read {}: {}", path.string(), why));
  };
  const std::string limit = fmt::format("the limit is {:.0f} MB", static_cast<double>(max_bytes) / 1048576.0);
  const int fd = open_regular_file(path, max_bytes, nullptr);
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
