// SWEEP.yaml: the grid is the cartesian product of its lists, first key
// slowest (oracle: the product written out by hand); listed cases follow;
// every bad input is one ConfigError naming the file and line.
#include <filesystem>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_files.hpp"
#include "twin/core/error.hpp"
#include "twin/sweep/sweep_spec.hpp"

namespace twin {
namespace {


std::filesystem::path write(const std::string& name, const std::string& text) {
  return test_support::write_file(std::filesystem::temp_directory_path() / "twin_sweep_spec_test" / name, text);
}

TEST(SweepSpec, GridIsTheProductFirstKeySlowestThenListedCases) {
  const auto p = write("grid.yaml",
                       "scenario: contour_square\n"
                       "set: [z.Kp=100]\n"
                       "log_every: 5\n"
                       "grid:\n"
                       "  machine: [fadal2216, fadal2216_cascade]\n"
                       "  set:\n"
                       "    x.Kp: [300, 600, 900]\n"
                       "cases:\n"
                       "  - {name: extra, set: [y.Kd=0.5]}\n");
  const sweep::SweepSpec s = sweep::load_sweep(p);
  ASSERT_EQ(s.cases.size(), 7u);
  EXPECT_EQ(s.log_every, 5);
  EXPECT_EQ(s.trace_format, "csv.gz");
  const char* machines[] = {"fadal2216", "fadal2216", "fadal2216", "fadal2216_cascade", "fadal2216_cascade",
                            "fadal2216_cascade"};
  const char* kp[] = {"300", "600", "900", "300", "600", "900"};
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(s.cases[i].index, i);
    EXPECT_EQ(s.cases[i].name, "case000" + std::to_string(i));
    EXPECT_EQ(s.cases[i].machine, machines[i]);
    ASSERT_EQ(s.cases[i].sets.size(), 2u);
    EXPECT_EQ(s.cases[i].sets[0], "z.Kp=100");  // the sweep-wide set first, the case's own after it
    EXPECT_EQ(s.cases[i].sets[1], std::string("x.Kp=") + kp[i]);
    ASSERT_EQ(s.cases[i].params.size(), 2u);
    EXPECT_EQ(s.cases[i].params[1].first, "x.Kp");
    EXPECT_EQ(s.cases[i].params[1].second, kp[i]);
    EXPECT_EQ(s.cases[i].scenario, "contour_square");
  }
  EXPECT_EQ(s.cases[6].name, "extra");
  EXPECT_EQ(s.cases[6].machine, "");
  const auto args = sweep::case_arguments(s, s.cases[3], "/o/c");
  const std::vector<std::string> expected{"run",          "contour_square", "-o",        "/o/c",
                                          "--no-plots",   "--trace-format", "csv.gz",    "--log-every",
                                          "5",            "--machine",      "fadal2216_cascade", "--set",
                                          "z.Kp=100",     "x.Kp=300"};
  EXPECT_EQ(args, expected);
}

TEST(SweepSpec, CalibrateFleetIsOneCasePerRun) {
  const auto p = write("fleet.yaml", "command: calibrate\nruns: [/data/a, /data/b]\n");
  const sweep::SweepSpec s = sweep::load_sweep(p);
  ASSERT_EQ(s.cases.size(), 2u);
  EXPECT_EQ(s.cases[1].run_dir, "/data/b");
  const auto args = sweep::case_arguments(s, s.cases[1], "/o/c");
  EXPECT_EQ(args, (std::vector<std::string>{"calibrate", "/data/b", "-o", "/o/c", "--no-plots"}));
}

TEST(SweepSpec, BadInputsAreOneLineNamingFileAndLine) {
  auto expect_error = [](const std::string& name, const std::string& text, const std::string& what) {
    const std::string message =
        test_support::expect_error<ConfigError>([&] { sweep::load_sweep(write(name, text)); }, name, what);
    EXPECT_EQ(message.find('\n'), std::string::npos) << name;
  };
  expect_error("unknown.yaml", "scenario: a\nfrobnicate: 1\n", "unknown.yaml:2: frobnicate: unknown key");
  expect_error("dup.yaml", "cases:\n  - {name: a}\n  - {name: a}\n", "case name 'a' is given twice");
  expect_error("set.yaml", "grid:\n  set:\n    xKp: [1, 2]\n", "set.yaml:3: grid.set.xKp: 'xKp=1' is not");
  expect_error("every.yaml", "log_every: 0.5\n", "must be a whole number");
  expect_error("fmt.yaml", "trace_format: parquet\n", "is not csv or csv.gz");
  expect_error("cmd.yaml", "command: tune\n", "a sweep runs 'run' or 'calibrate'");
  expect_error("norun.yaml", "command: calibrate\n", "names no measured run");
  expect_error("name.yaml", "cases:\n  - {name: ../x}\n", "a case name is letters");
  expect_error("list.yaml", "grid:\n  machine: []\n", "must be a value or a non-empty list");
}

}  // namespace
}  // namespace twin
