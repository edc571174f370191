// The command-line program as a user meets it: every subcommand has --help;
// every bad input gives exactly one line on stderr, a non-zero exit and no
// file at a final name in OUT.
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

namespace twin {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

struct Result {
  int exit_code{0};
  std::string out;
  std::string err;
};

// One folder per test: ctest runs the tests of this file in parallel.
std::filesystem::path work() {
  const auto d = std::filesystem::temp_directory_path() / "twin_cli_test" /
                 ::testing::UnitTest::GetInstance()->current_test_info()->name();
  std::filesystem::create_directories(d);
  return d;
}

std::string slurp(const std::filesystem::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

Result twin_cmd(const std::string& args) {
  const auto out = work() / "stdout.txt";
  const auto err = work() / "stderr.txt";
  const std::string cmd = std::string(TWIN_BINARY_DIR) + "/bin/twin " + args + " >" + out.string() + " 2>" +
                          err.string() + " </dev/null";
  const int rc = std::system(cmd.c_str());
  Result r;
  r.exit_code = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

int lines(const std::string& s) {
  int n = 0;
  for (char c : s) n += c == '\n';
  return n;
}

void expect_one_line_failure(const Result& r, const std::string& what) {
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(lines(r.err), 1) << r.err;
  EXPECT_THAT(r.err, HasSubstr(what));
}

std::filesystem::path file(const std::string& name, const std::string& text) {
  const auto p = work() / name;
  std::filesystem::create_directories(p.parent_path());
  std::ofstream(p) << text;
  return p;
}

TEST(Cli, HelpForEverySubcommand) {
  for (const char* sub : {"", "run", "replay", "bench", "cut", "tune", "calibrate", "export-fmu"}) {
    const Result r = twin_cmd(std::string(sub) + " --help");
    EXPECT_EQ(r.exit_code, 0) << sub;
    EXPECT_THAT(r.out, HasSubstr("Usage")) << sub;
  }
}

TEST(Cli, BadInputsFailWithOneLineAndNoFiles) {
  const auto out = work() / "out_bad";
  std::filesystem::remove_all(out);
  expect_one_line_failure(twin_cmd("run nosuch_scenario -o " + out.string()), "nosuch_scenario");
  expect_one_line_failure(twin_cmd("run -o " + out.string() + " --set x.Jay=1"), "Jay");
  expect_one_line_failure(twin_cmd("run -o " + out.string() + " --set x.J=-1"), "J");
  expect_one_line_failure(twin_cmd("frobnicate"), "frobnicate");
  // A malformed program: the message names the file and the line.
  const auto prog = file("badprog/program.nc", "G21 G90\nG1 X10 F1000\nG1 X1Q0\n");
  const auto scen = file("badprog/scenario.yaml",
                         "name: badprog\nmachine: fadal2216\nprogram: program.nc\nstart_mm: [0, 0, 0]\n");
  expect_one_line_failure(twin_cmd("run " + scen.string() + " -o " + out.string()), prog.string() + ":3");
  // An unknown scenario key.
  const auto scen2 = file("badkey/scenario.yaml",
                          "name: badkey\nmachine: fadal2216\nprogram: ../badprog/program.nc\nspeed: 3\n");
  expect_one_line_failure(twin_cmd("run " + scen2.string() + " -o " + out.string()), "speed");
  // A replay of a run with a NaN.
  file("nanrun/meta.json", R"({"machine": "fadal2216", "controller_period_s": 0.0001})");
  file("nanrun/trace.csv", "t_s,x_ref_mm\n0,0\n0.0001,NaN\n");
  expect_one_line_failure(twin_cmd("replay " + (work() / "nanrun").string() + " -o " + out.string()), ":3");
  // Unstable gains: detected, named, and no trace left behind.
  const auto prog3 = file("unstable/program.nc", "G21 G90\nG1 X5 F1000\nM30\n");
  const auto scen3 = file("unstable/scenario.yaml",
                          "name: unstable\nmachine: fadal2216\nprogram: program.nc\nstart_mm: [0, 0, 0]\n");
  static_cast<void>(prog3);
  expect_one_line_failure(twin_cmd("run " + scen3.string() + " -o " + out.string() + " --set x.Ki=2000000"),
                          "axis x");
  if (std::filesystem::exists(out)) {
    for (const auto& e : std::filesystem::directory_iterator(out))
      ADD_FAILURE() << "left behind: " << e.path();
  }
}

TEST(Cli, RunWritesTraceSummaryAndPlots) {
  const auto prog = file("small/program.nc", "G21 G90 G64 P0.01\nG1 X10 F2000\nY10\nM30\n");
  static_cast<void>(prog);
  const auto scen = file("small/scenario.yaml",
                         "name: small\nmachine: fadal2216\nprogram: program.nc\nstart_mm: [0, 0, 0]\nsettle_s: 0.02\n");
  const auto out = work() / "out_small";
  std::filesystem::remove_all(out);
  const Result r = twin_cmd("run " + scen.string() + " -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"trace.csv", "summary.json", "feedrate.png", "errors.png"})
    EXPECT_TRUE(std::filesystem::exists(out / f)) << f;
  const std::string header = slurp(out / "trace.csv").substr(0, 200);
  EXPECT_THAT(header, HasSubstr("t_s,x_ref_mm,x_mm,x_u_V,x_i_A,y_ref_mm"));
  EXPECT_THAT(slurp(out / "summary.json"), HasSubstr("\"cycle_time_s\""));
}

// A run as real machines log it: from a machine the meta does not name, with
// y's reference but not its measured position. The twin's own simulated trace
// (twin run) stands in for the measurement. calibrate must finish, write its
// report, model, trace and residual plots (for x, the axis it can compare),
// and say in report.md what it assumed and what it could not do.
// An axis that stands still over the held-out rows has a tracking error and
// a u of zero there: their NRMS cannot be computed, and report.json says so
// (null and the reason) instead of reporting a perfect 0.
TEST(Cli, CalibrateSaysWhichErrorsItCouldNotCompute) {
  const auto run = work() / "still_run";
  std::filesystem::create_directories(run);
  std::ofstream(run / "meta.json") << R"({"machine": "fadal2216", "axes": ["x"], "controller_period_s": 0.0001, )"
                                      R"("sample_period_s": 0.0001, "encoder_resolution_mm": 0.001})";
  {
    std::ofstream t(run / "trace.csv");
    t << "t_s,x_ref_mm,x_mm,x_u_V\n";
    for (int k = 0; k < 400; ++k) t << k * 1e-4 << ",10,10,0\n";
  }
  const auto out = work() / "out_still";
  std::filesystem::remove_all(out);
  const Result r = twin_cmd("calibrate " + run.string() + " -o " + out.string() + " --no-plots");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string report = slurp(out / "report.json");
  EXPECT_THAT(report, HasSubstr("\"x_err_mm\": null"));
  EXPECT_THAT(report, HasSubstr("\"x_u_V\": null"));
  EXPECT_THAT(report, HasSubstr("the axis does not move there"));
}

// The cascade law from the command line: the shipped example machine runs the
// default scenario (its P loop lags by v (1 - kff) / Kv: a contour error of
// tens of microns where the FADAL PID keeps about two); tune, whose linear
// analysis covers the FADAL law, says so in one line instead of tuning it.
TEST(Cli, CascadeMachineRunsAndTuneSaysWhatItCovers) {
  const auto out = work() / "out_cascade";
  std::filesystem::remove_all(out);
  const Result r = twin_cmd("run --machine fadal2216_cascade --no-plots -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(out / "summary.json"));
  const Result t = twin_cmd("tune --machine fadal2216_cascade -o " + (work() / "out_tune").string());
  EXPECT_NE(t.exit_code, 0);
  EXPECT_EQ(lines(t.err), 1) << t.err;
  EXPECT_THAT(t.err, HasSubstr("cascade"));
}

TEST(Cli, CalibrateRunOfAnUnnamedMachineWithAnAxisUnmeasured) {
  const auto prog = file("partial/program.nc", "G21 G90 G64 P0.01\nG1 X10 Y5 F3000\nX0 Y0\nX10\nX0\nM30\n");
  static_cast<void>(prog);
  const auto scen = file("partial/scenario.yaml",
                         "name: partial\nmachine: fadal2216\nprogram: program.nc\nstart_mm: [0, 0, 0]\nsettle_s: 0.05\n");
  const auto sim = work() / "sim";
  std::filesystem::remove_all(sim);
  const Result made = twin_cmd("run " + scen.string() + " -o " + sim.string() + " --no-plots");
  ASSERT_EQ(made.exit_code, 0) << made.err;
  // Keep t_s, x_ref_mm, x_mm, x_u_V and y_ref_mm of the simulated trace.
  std::ifstream in(sim / "trace.csv");
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  {
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) header.push_back(c);
  }
  const std::vector<std::string> keep{"t_s", "x_ref_mm", "x_mm", "x_u_V", "y_ref_mm"};
  std::vector<std::size_t> idx;
  for (const auto& k : keep) {
    const auto it = std::find(header.begin(), header.end(), k);
    ASSERT_NE(it, header.end()) << k;
    idx.push_back(static_cast<std::size_t>(it - header.begin()));
  }
  std::string csv = "t_s,x_ref_mm,x_mm,x_u_V,y_ref_mm\n";
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    for (std::size_t j = 0; j < idx.size(); ++j) csv += cells.at(idx[j]) + (j + 1 < idx.size() ? "," : "\n");
  }
  file("partial_run/trace.csv", csv);
  file("partial_run/meta.json", R"({"machine": null, "axes": ["x", "y"], "controller_period_s": 0.0001, )"
                                R"("sample_period_s": 0.0001, "encoder_resolution_mm": 0.001})");
  const auto out = work() / "out_partial";
  std::filesystem::remove_all(out);
  const Result r = twin_cmd("calibrate " + (work() / "partial_run").string() + " -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"report.json", "report.md", "machine.yaml", "trace.csv", "trace_before.csv"})
    EXPECT_TRUE(std::filesystem::exists(out / f)) << f;
  const std::string report = slurp(out / "report.md");
  // A run naming no machine is calibrated from its data alone (no FADAL prior):
  // x from its logged u, y (reference only) said and left out.
  EXPECT_THAT(report, HasSubstr("name no machine"));
  EXPECT_THAT(report, HasSubstr("axis y: no torque, current or command channel"));
  EXPECT_THAT(report, Not(HasSubstr("plots not drawn")));
  EXPECT_TRUE(std::filesystem::exists(out / "overlay.png") || report.find("gnuplot") != std::string::npos);
}

}  // namespace
}  // namespace twin
