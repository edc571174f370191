#include "twin/sweep/runner.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <algorithm>
#include <optional>
#include <thread>

#include <fmt/format.h>

#if TWIN_WITH_MPI
#include <mpi.h>
#endif

#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/yaml_util.hpp"

extern char** environ;

namespace twin::sweep {

namespace {

std::filesystem::path case_dir(const std::filesystem::path& out, const SweepCase& c) { return out / "cases" / c.name; }
std::filesystem::path log_path(const std::filesystem::path& out, const SweepCase& c) {
  return out / "logs" / (c.name + ".log");
}

// The last non-empty line of the case's log: its one-line reason.
std::string last_line(const std::filesystem::path& log) {
  std::string text;
  try {
    text = io::read_file(log, std::uintmax_t{64} << 20);
  } catch (const Error&) {
    return "no log";
  }
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ')) text.pop_back();
  const auto nl = text.rfind('\n');
  return io::escaped(nl == std::string::npos ? text : text.substr(nl + 1), 300);
}

// Numbers and text of a summary or report, nested maps as dotted names;
// lists are left out (per-block and per-corner detail stays in the case's
// folder), except the calibration's added effects, listed as effect:axis.
void flatten(const nlohmann::json& j, const std::string& prefix, Row& out) {
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string key = prefix.empty() ? it.key() : prefix + "." + it.key();
    const auto& v = it.value();
    if (v.is_object()) {
      flatten(v, key, out);
    } else if (v.is_array()) {
      if (key != "effects_added") continue;
      std::string list;
      for (const auto& e : v) {
        if (!e.is_object()) continue;
        if (!list.empty()) list += ';';
        list += e.value("effect", std::string("?"));
        if (e.contains("axis") && e["axis"].is_string()) list += ":" + e["axis"].get<std::string>();
      }
      out[key] = list;
    } else if (v.is_number() || v.is_boolean() || v.is_string()) {
      out[out.contains(key) ? "result." + key : key] = v;
    }
  }
}

pid_t spawn_case(const SweepSpec& spec, const SweepCase& c, const RunnerOptions& o) {
  io::ensure_directory(o.out_dir / "cases");
  io::ensure_directory(o.out_dir / "logs");
  const std::vector<std::string> args = case_arguments(spec, c, case_dir(o.out_dir, c));
  std::vector<char*> argv;
  std::string exe = o.twin_exe.string();
  argv.push_back(exe.data());
  std::vector<std::string> store(args);
  for (auto& a : store) argv.push_back(a.data());
  argv.push_back(nullptr);
  const std::string log = log_path(o.out_dir, c).string();
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&fa, 1, 2);
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, exe.c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) throw IoError(fmt::format("cannot start {} for case {}: {}", exe, c.name, std::strerror(rc)));
  return pid;
}

// Cases running as child processes of this process, at most `jobs` at once.
class Pool {
 public:
  Pool(const SweepSpec& spec, const RunnerOptions& o) : spec_(spec), o_(o) {}
  ~Pool() {
    for (const auto& r : running_) {  // an error ends the sweep: its cases end with it
      ::kill(r.pid, SIGTERM);
      int st = 0;
      ::waitpid(r.pid, &st, 0);
    }
  }
  Pool(const Pool&) = delete;
  Pool& operator=(const Pool&) = delete;
  bool has_room() const noexcept { return running_.size() < static_cast<std::size_t>(std::max(1, o_.jobs)); }
  std::size_t running() const noexcept { return running_.size(); }
  void start(std::size_t index) { running_.push_back({spawn_case(spec_, spec_.cases.at(index), o_), index}); }
  /// The cases that ended since the last call, as rows (never blocks).
  std::vector<std::pair<std::size_t, Row>> poll() {
    std::vector<std::pair<std::size_t, Row>> done;
    for (std::size_t i = 0; i < running_.size();) {
      int st = 0;
      const pid_t r = ::waitpid(running_[i].pid, &st, WNOHANG);
      if (r == running_[i].pid) {
        const std::size_t index = running_[i].index;
        done.emplace_back(index, case_row(spec_, spec_.cases[index], o_.out_dir, st));
        running_.erase(running_.begin() + static_cast<std::ptrdiff_t>(i));
      } else {
        ++i;
      }
    }
    return done;
  }

 private:
  struct Child {
    pid_t pid;
    std::size_t index;
  };
  const SweepSpec& spec_;
  const RunnerOptions& o_;
  std::vector<Child> running_;
};

void nap() { std::this_thread::sleep_for(std::chrono::milliseconds(2)); }

/// The rows of a sweep as they come in, in case order, with the progress report.
class RowCollector {
 public:
  RowCollector(std::size_t n, const RunnerOptions& options) : rows_(n), options_(options) {}
  void record(std::size_t index, Row row) {
    failed_ += row["status"] == "failed";
    rows_.at(index) = std::move(row);
    ++done_;
    if (options_.progress) options_.progress(done_, failed_, rows_.size());
  }
  bool all_done() const { return done_ >= rows_.size(); }
  std::vector<Row> take() { return std::move(rows_); }

 private:
  std::vector<Row> rows_;
  const RunnerOptions& options_;
  std::size_t done_{0}, failed_{0};
};

std::string csv_field(const nlohmann::ordered_json& v) {
  if (v.is_null()) return "";
  if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
  if (v.is_number_integer()) return std::to_string(v.get<std::int64_t>());
  if (v.is_number_unsigned()) return std::to_string(v.get<std::uint64_t>());
  if (v.is_number()) {
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof buf, v.get<double>());  // shortest round trip
    return std::string(buf, r.ptr);
  }
  std::string s = v.is_string() ? v.get<std::string>() : v.dump();
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char ch : s) {
    if (ch == '"') q += '"';
    q += ch;
  }
  return q + "\"";
}

}  // namespace

Row case_row(const SweepSpec& spec, const SweepCase& c, const std::filesystem::path& out_dir, int status) {
  Row row;
  row["case"] = c.index;
  row["name"] = c.name;
  row["status"] = "ok";
  row["error"] = "";
  for (const auto& [k, v] : c.params) row[k] = v;
  std::string error;
  if (WIFSIGNALED(status)) {
    error = fmt::format("ended by signal {}", WTERMSIG(status));
  } else if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    error = last_line(log_path(out_dir, c));
  } else {
    const auto file = case_dir(out_dir, c) / (spec.command == "calibrate" ? "report.json" : "summary.json");
    try {
      const nlohmann::json j = nlohmann::json::parse(io::read_file(file));
      flatten(j, "", row);
    } catch (const std::exception& e) {
      error = fmt::format("{}: {}", file.filename().string(), io::escaped(e.what(), 200));
    }
  }
  if (!error.empty()) {
    row["status"] = "failed";
    row["error"] = error;
  }
  return row;
}

std::vector<Row> run_local(const SweepSpec& spec, const RunnerOptions& options) {
  const std::size_t n = spec.cases.size();
  RowCollector rows(n, options);
  std::size_t next = 0;
  Pool pool(spec, options);
  while (!rows.all_done()) {
    while (next < n && pool.has_room()) pool.start(next++);
    auto finished = pool.poll();
    if (finished.empty()) nap();
    for (auto& [index, row] : finished) rows.record(index, std::move(row));
  }
  return rows.take();
}

bool launched_by_mpi() noexcept {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK", "PMI_SIZE"})
    if (std::getenv(v) != nullptr) return true;
  return false;
}

#if TWIN_WITH_MPI

bool mpi_built() noexcept { return true; }

namespace {
constexpr int kTagToRoot = 1;   // a worker's message: {"want": bool, "row": Row or null} or {"bye": true}
constexpr int kTagAssign = 2;   // the root's answer to a want: a case index, or -1 (no more)

class MpiSession {
 public:
  MpiSession() { MPI_Init(nullptr, nullptr); }
  ~MpiSession() { MPI_Finalize(); }
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
};

void send_text(const std::string& text) {
  MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, 0, kTagToRoot, MPI_COMM_WORLD);
}
}  // namespace

namespace {

/// Rank 0: runs cases itself between answering the other ranks' asks (a case
/// index, or -1 when there are no more) and gathers their rows, until every
/// case is done and every other rank has said goodbye.
std::vector<Row> run_root(const SweepSpec& spec, const RunnerOptions& options, Pool& pool, int size) {
  const std::size_t n = spec.cases.size();
  RowCollector rows(n, options);
  std::size_t next = 0;
  int byes = 0;
  while (!rows.all_done() || byes < size - 1) {
    bool idle = true;
    while (next < n && pool.has_room()) pool.start(next++);
    for (auto& [index, row] : pool.poll()) {
      rows.record(index, std::move(row));
      idle = false;
    }
    int flag = 0;
    MPI_Status st;
    MPI_Iprobe(MPI_ANY_SOURCE, kTagToRoot, MPI_COMM_WORLD, &flag, &st);
    if (flag) {
      idle = false;
      int count = 0;
      MPI_Get_count(&st, MPI_CHAR, &count);
      std::string text(static_cast<std::size_t>(count), '\0');
      MPI_Recv(text.data(), count, MPI_CHAR, st.MPI_SOURCE, kTagToRoot, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      const nlohmann::ordered_json m = nlohmann::ordered_json::parse(text);
      if (m.contains("bye")) {
        ++byes;
      } else {
        if (!m["row"].is_null()) rows.record(m["row"]["case"].get<std::size_t>(), m["row"]);
        if (m["want"].get<bool>()) {
          const long long assign = next < n ? static_cast<long long>(next++) : -1;
          MPI_Send(&assign, 1, MPI_LONG_LONG, st.MPI_SOURCE, kTagAssign, MPI_COMM_WORLD);
        }
      }
    }
    if (idle) nap();
  }
  return rows.take();
}

/// A worker: asks for one case per free slot, runs it, sends its row back
/// with the next ask, until the root says there are no more.
void run_worker(const RunnerOptions& options, Pool& pool) {
  const int slots = std::max(1, options.jobs);
  int outstanding = 0;
  bool stopped = false;
  for (int s = 0; s < slots; ++s) {
    send_text(R"({"want":true,"row":null})");
    ++outstanding;
  }
  while (outstanding > 0 || pool.running() > 0) {
    bool idle = true;
    int flag = 0;
    MPI_Iprobe(0, kTagAssign, MPI_COMM_WORLD, &flag, MPI_STATUS_IGNORE);
    if (flag) {
      idle = false;
      long long assign = -1;
      MPI_Recv(&assign, 1, MPI_LONG_LONG, 0, kTagAssign, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
      --outstanding;
      if (assign < 0) stopped = true;
      else pool.start(static_cast<std::size_t>(assign));
    }
    for (auto& [index, row] : pool.poll()) {
      idle = false;
      nlohmann::ordered_json m;
      m["want"] = !stopped;
      m["row"] = std::move(row);
      send_text(m.dump());
      if (!stopped) ++outstanding;
    }
    if (idle) nap();
  }
  send_text(R"({"bye":true})");
}

std::vector<Row> run_ranks(const SweepSpec& spec, const RunnerOptions& options, bool* is_root, int* ranks) {
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  *is_root = rank == 0;
  *ranks = size;
  Pool pool(spec, options);
  if (rank == 0) return run_root(spec, options, pool, size);
  run_worker(options, pool);
  return {};
}
}  // namespace

std::vector<Row> run_mpi(const SweepSpec& spec, const RunnerOptions& options, bool* is_root, int* ranks) {
  MpiSession session;
  try {
    return run_ranks(spec, options, is_root, ranks);
  } catch (const std::exception& e) {
    // The other ranks wait on this one: end them all rather than hang.
    int rank = 0;
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    std::fprintf(stderr, "twin sweep: rank %d: %s\n", rank, e.what());
    std::fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 1);
    throw;
  }
}

void abort_mpi(int code) noexcept {
  int initialised = 0, finalised = 0;
  MPI_Initialized(&initialised);
  MPI_Finalized(&finalised);
  if (initialised && !finalised) MPI_Abort(MPI_COMM_WORLD, code);
}

#else

bool mpi_built() noexcept { return false; }

std::vector<Row> run_mpi(const SweepSpec&, const RunnerOptions&, bool*, int*) {
  throw InternalError("twin was built without MPI");
}

void abort_mpi(int) noexcept {}

#endif

std::string results_csv(const std::vector<Row>& rows) {
  std::vector<std::string> columns;
  for (const auto& r : rows)
    for (auto it = r.begin(); it != r.end(); ++it)
      if (std::find(columns.begin(), columns.end(), it.key()) == columns.end()) columns.push_back(it.key());
  std::string out;
  for (std::size_t i = 0; i < columns.size(); ++i) out += (i ? "," : "") + columns[i];
  out += '\n';
  for (const auto& r : rows) {
    for (std::size_t i = 0; i < columns.size(); ++i) {
      if (i) out += ',';
      if (r.contains(columns[i])) out += csv_field(r[columns[i]]);
    }
    out += '\n';
  }
  return out;
}

}  // namespace twin::sweep
