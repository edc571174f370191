#pragma once
// Set-up shared by the tests that write files and run the twin executable:
// a folder per test, a file's text, a command's exit status and output, a
// reader's error, the shipped scenarios. Header only; TWIN_SOURCE_DIR and TWIN_BINARY_DIR come
// from twin_add_test (tests/CMakeLists.txt).
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace twin::test_support {

/// The name of the test that is running (its parameter's index included for a TEST_P).
inline std::string current_test_name() { return ::testing::UnitTest::GetInstance()->current_test_info()->name(); }

/// `dir`, created with its parents when missing (what is in it is kept).
inline std::filesystem::path made_dir(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  return dir;
}

/// `path`, removed with what is in it (a run's output folder not yet written).
inline std::filesystem::path removed(const std::filesystem::path& path) {
  std::filesystem::remove_all(path);
  return path;
}

/// `dir`, emptied: removed with what is in it and created again.
inline std::filesystem::path fresh_dir(const std::filesystem::path& dir) { return made_dir(removed(dir)); }

/// Writes `text` to `path` (its folder created when missing) and returns `path`.
inline std::filesystem::path write_file(const std::filesystem::path& path, const std::string& text) {
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  std::ofstream(path) << text;
  return path;
}

/// The bytes of a file ("" when it cannot be read).
inline std::string slurp(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// The twin executable of this build tree.
inline std::string twin_exe() { return std::string(TWIN_BINARY_DIR) + "/bin/twin"; }

struct CommandResult {
  int exit_code{0};  ///< the exit status; -1 when the command did not exit
  std::string out;   ///< what it wrote to stdout
  std::string err;   ///< what it wrote to stderr
};

/// Runs a shell command with no input, its stdout and stderr kept in
/// dir/stdout.txt and dir/stderr.txt.
inline CommandResult run_command(const std::filesystem::path& dir, const std::string& command) {
  const auto out = dir / "stdout.txt";
  const auto err = dir / "stderr.txt";
  const std::string cmd = command + " >" + out.string() + " 2>" + err.string() + " </dev/null";
  const int rc = std::system(cmd.c_str());
  return {WIFEXITED(rc) ? WEXITSTATUS(rc) : -1, slurp(out), slurp(err)};
}

/// Expects `load()` to throw an E whose message holds `what` (a failure
/// naming `name` when it throws nothing); returns the message ("" then).
template <class E, class Load>
std::string expect_error(Load&& load, const std::string& name, const std::string& what) {
  try {
    load();
    ADD_FAILURE() << name << ": no error";
  } catch (const E& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr(what)) << name;
    return e.what();
  }
  return {};
}

/// The names of the scenarios shipped in scenarios/ (each folder with a
/// scenario.yaml), sorted.
inline std::vector<std::string> shipped_scenarios() {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios"))
    if (std::filesystem::exists(e.path() / "scenario.yaml")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace twin::test_support
