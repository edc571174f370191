// The command-line program as a user meets it: every subcommand has --help;
// every bad input gives exactly one line on stderr, a non-zero exit and no
// file at a final name in OUT.

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_files.hpp"

namespace twin {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

using Result = test_support::CommandResult;
using test_support::slurp;

std::filesystem::path work() {
  return test_support::made_dir(std::filesystem::temp_directory_path() / "twin_cli_test" /
                                test_support::current_test_name());
}

Result twin_cmd(const std::string& args) { return test_support::run_command(work(), test_support::twin_exe() + " " + args); }

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
  return test_support::write_file(work() / name, text);
}

/// DIR/program.nc holding `program` and DIR/scenario.yaml running it on the fadal2216 (`extra` appended).
std::filesystem::path scenario_with(const std::string& dir, const std::string& program,
                                    const std::string& extra = "start_mm: [0, 0, 0]\n") {
  file(dir + "/program.nc", program);
  return file(dir + "/scenario.yaml", "name: " + dir + "\nmachine: fadal2216\nprogram: program.nc\n" + extra);
}

TEST(Cli, HelpForEverySubcommand) {
  for (const char* sub : {"", "run", "replay", "bench", "cut", "tune", "calibrate", "export-fmu"}) {
    const Result r = twin_cmd(std::string(sub) + " --help");
    EXPECT_EQ(r.exit_code, 0) << sub;
    EXPECT_THAT(r.out, HasSubstr("Usage")) << sub;
  }
}

TEST(Cli, BadInputsFailWithOneLineAndNoFiles) {
  const auto out = test_support::removed(work() / "out_bad");
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
  const auto scen = scenario_with("small", "G21 G90 G64 P0.01\nG1 X10 F2000\nY10\nM30\n",
                                  "start_mm: [0, 0, 0]\nsettle_s: 0.02\n");
  const auto out = test_support::removed(work() / "out_small");
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
  const auto out = test_support::removed(work() / "out_still");
  const Result r = twin_cmd("calibrate " + run.string() + " -o " + out.string() + " --no-plots");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string report = slurp(out / "report.json");
  EXPECT_THAT(report, HasSubstr("\"x_err_mm\": null"));
  EXPECT_THAT(report, HasSubstr("\"x_u_V\": null"));
  EXPECT_THAT(report, HasSubstr("the axis does not move there"));
}

// The cascade law from the command line: the shipped example machine runs the
// default scenario (its P loop lags by v (1 - kff) / Kv: a contour error of
// tens of microns where the FADAL PID keeps about two); `tune --axis all` tunes
// its cascade gains and writes them under the machine file's names.
TEST(Cli, CascadeMachineRunsAndTunes) {
  const auto out = test_support::removed(work() / "out_cascade");
  const Result r = twin_cmd("run --machine fadal2216_cascade --no-plots -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(out / "summary.json"));
  const auto tuned = test_support::removed(work() / "out_tune");
  const Result t = twin_cmd("tune --machine fadal2216_cascade --axis all --max-evals 8 --check none --no-plots -o " +
                            tuned.string());
  ASSERT_EQ(t.exit_code, 0) << t.err;
  EXPECT_THAT(t.out, HasSubstr("axis x: Kv "));
  const std::string yaml = slurp(tuned / "machine.yaml");
  EXPECT_THAT(yaml, HasSubstr("controller: cascade"));
  EXPECT_THAT(yaml, HasSubstr("Kvp:"));
}

TEST(Cli, CalibrateRunOfAnUnnamedMachineWithAnAxisUnmeasured) {
  const auto scen = scenario_with("partial", "G21 G90 G64 P0.01\nG1 X10 Y5 F3000\nX0 Y0\nX10\nX0\nM30\n",
                                  "start_mm: [0, 0, 0]\nsettle_s: 0.05\n");
  const auto sim = test_support::removed(work() / "sim");
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
  const auto out = test_support::removed(work() / "out_partial");
  const Result r = twin_cmd("calibrate " + (work() / "partial_run").string() + " -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"report.json", "report.md", "machine.yaml", "trace.csv", "trace_before.csv"})
    EXPECT_TRUE(std::filesystem::exists(out / f)) << f;
  const std::string report = slurp(out / "report.md");
  // A run naming no machine is calibrated from its data alone (no FADAL prior):
  // x from its logged u, y (reference only) said and left out.
  EXPECT_THAT(report, HasSubstr("name no machine"));
  EXPECT_THAT(report, HasSubstr("axis y: no torque, current or command channel"));
  // Every effect tried is listed once, kept or not, with why (rising_friction
  // is tried on every axis the drive is identified on).
  EXPECT_THAT(report, HasSubstr("## Effects tried"));
  EXPECT_THAT(report, HasSubstr("- rising_friction on x"));
  // x moves both ways: whether it has one Coulomb level or two is said, with why.
  EXPECT_THAT(report, HasSubstr("- Coulomb levels: "));
  EXPECT_THAT(report, Not(HasSubstr("plots not drawn")));
  EXPECT_TRUE(std::filesystem::exists(out / "overlay.png") || report.find("gnuplot") != std::string::npos);
}

// A user's log from a machine the twin does not ship, stitched from two
// recordings 70 mm apart: `twin replay` with the shipped machine standing in
// replays each piece from its own start, as calibrate does, and says so. Read
// straight through, the stand-in's loop would chase the 70 mm step and stop at
// its following-error limit. Oracle: the log itself. Each piece starts at rest
// on its reference, so the replayed position at the first row after the
// stitch is that row's reference; the tolerance is the 1 um of the encoder.
TEST(Cli, ReplayOfAStitchedLogReplaysEachPieceFromItsOwnStart) {
  std::string csv = "t_s,x_ref_mm,x_mm,x_i_A\n";
  const double pi = 3.14159265358979;
  const std::size_t stitch_row = 600;
  for (int k = 0; k < 1200; ++k) {
    // 10 mm out and back in 0.25 s each (a cosine ramp), resting between;
    // the second recording, from row 600, 70 mm further along.
    const int j = k % 600;
    double s = 0.0;
    if (j < 250)
      s = 0.5 * (1 - std::cos(pi * j / 250.0));
    else if (j < 300)
      s = 1.0;
    else if (j < 550)
      s = 0.5 * (1 + std::cos(pi * (j - 300) / 250.0));
    const double x = 10.0 * s + (k >= 600 ? 70.0 : 0.0);
    csv += std::to_string(k * 1e-3) + "," + std::to_string(x) + "," + std::to_string(x) + ",0\n";
  }
  file("stitched_run/trace.csv", csv);
  file("stitched_run/meta.json", R"({"machine": null, "axes": ["x"], "sample_period_s": 0.001})");
  const auto out = test_support::removed(work() / "out_stitched");
  const Result r = twin_cmd("replay " + (work() / "stitched_run").string() + " -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("stitched from 2 segments"));
  // What both pieces' replays say is said once.
  const std::string said = "their mean over the two sample periods around it";
  ASSERT_THAT(r.err, HasSubstr(said));
  EXPECT_EQ(r.err.find(said), r.err.rfind(said));
  EXPECT_TRUE(std::filesystem::exists(out / "errors.json"));
  std::ifstream in(out / "trace.csv");
  std::string line;
  std::getline(in, line);
  EXPECT_THAT(line, HasSubstr("t_s,x_ref_mm,x_mm"));
  for (std::size_t k = 0; k <= stitch_row; ++k) ASSERT_TRUE(std::getline(in, line));
  std::vector<double> cells;
  std::stringstream ss(line);
  for (std::string c; std::getline(ss, c, ',');) cells.push_back(std::stod(c));
  ASSERT_GE(cells.size(), 3u);
  EXPECT_NEAR(cells[1], 70.0, 1e-9);
  EXPECT_NEAR(cells[2], cells[1], 1e-3);
}

// ---------------------------------------------------------------------------
// Hostile inputs (issue 19). Each must end, within the test's own bound, in
// one line on stderr naming the file and line (or key), a non-zero exit and
// no file at a final name. Oracle: the input itself (what it asks for, a
// duration, a span, a size, is known by construction) and the error contract
// of the readers. A hang is bounded by `timeout` (exit 124 fails the test).

Result twin_bounded(const std::string& args, int seconds = 120) {
  return test_support::run_command(work(), "timeout -k 5 " + std::to_string(seconds) + " " + test_support::twin_exe() +
                                               " " + args);
}

/// `twin run` of a scenario made by scenario_with(dir, program) into `out`, with `flags`.
Result run_program(const std::string& dir, const std::string& program, const std::filesystem::path& out,
                   const std::string& flags = "") {
  return twin_bounded("run " + scenario_with(dir, program).string() + " -o " + out.string() + flags);
}

void expect_no_files(const std::filesystem::path& out) {
  if (!std::filesystem::exists(out)) return;
  for (const auto& e : std::filesystem::directory_iterator(out)) ADD_FAILURE() << "left behind: " << e.path();
}

TEST(CliHostile, NonFiniteOrAstronomicalDurationsRefusedWithTheLine) {
  const auto out = test_support::removed(work() / "out");
  // X1 followed by 300 zeros: 1e300 mm, a planned duration beyond any tick count.
  expect_one_line_failure(run_program("inf", "G21 G90\nG1 X1" + std::string(300, '0') + " F1000\nM30\n", out),
                          "inf/program.nc:2");
  // Two incremental moves of 1e307 mm.
  const std::string big = "1" + std::string(307, '0');
  expect_one_line_failure(run_program("g91", "G21 G91\nG1 X" + big + " F1000\nX" + big + "\nM30\n", out),
                          "g91/program.nc:2");
  // A start position no machine reaches.
  const auto s3 = scenario_with("start", "G21 G90\nG1 Y10 F1000\nM30\n", "start_mm: [1e300, 0, 0]\n");
  expect_one_line_failure(twin_bounded("run " + s3.string() + " -o " + out.string()), "start_mm[0]");
  expect_no_files(out);
}

TEST(CliHostile, MovesBeyondTheTravelRefusedWithTheLine) {
  const auto out = test_support::removed(work() / "out");
  // fadal2216: x travel 559 mm, y 406 mm, z 508 mm.
  const Result r1 = run_program("rapid", "G21 G90\nG1 X10 F1000\nG0 X700 Y-100 Z-300\nM30\n", out);
  expect_one_line_failure(r1, "rapid/program.nc:3");
  EXPECT_THAT(r1.err, HasSubstr("travel of 559 mm"));
  // An arc whose ends are 20 mm apart in y but which, counter-clockwise the
  // long way round its centre (300, 10) of radius 300.2 mm, reaches x = 600 mm.
  const Result r2 = run_program("bulge", "G21 G90\nG3 X0 Y20 I300 J10 F1000\nM30\n", out);
  expect_one_line_failure(r2, "bulge/program.nc:2");
  EXPECT_THAT(r2.err, HasSubstr("in x"));
  // An arc of radius 1e12 mm (a full circle: start = end).
  expect_one_line_failure(run_program("huge_arc", "G21 G90\nG2 X0 Y0 I1000000000000 F1000\nM30\n", out),
                          "huge_arc/program.nc:2");
  expect_no_files(out);
  // The whole travel is allowed: a 559 mm move in x reaches the planning
  // stage (and is refused there only by the budget asked for here).
  const Result r4 = run_program("full", "G21 G90\nG0 X559\nM30\n", out, " --max-duration-s 0.001");
  expect_one_line_failure(r4, "--max-duration-s");
}

TEST(CliHostile, LongRunsRefusedBeforeSimulatingWithBothFigures) {
  const auto out = test_support::removed(work() / "out");
  // A dwell of 1e9 s: 1e13 ticks of 1e-4 s.
  const Result r1 = run_program("dwell", "G21 G90\nG4 P1000000000\nM30\n", out);
  expect_one_line_failure(r1, "--max-duration-s");
  EXPECT_THAT(r1.err, HasSubstr("--max-trace-mb"));
  EXPECT_THAT(r1.err, HasSubstr("1e+09 s"));
  expect_no_files(out);
  // Ts = 1e-9 s on a 10 mm move: about 1e9 ticks, a trace of hundreds of GB.
  const auto s2 = scenario_with("fine", "G21 G90\nG1 X10 F1000\nM30\n");
  const Result r2 = twin_bounded("run " + s2.string() + " -o " + out.string() + " --set Ts=1e-9");
  expect_one_line_failure(r2, "--max-trace-mb");
  expect_no_files(out);
  // The flags set the limits: the same small program is refused under a
  // 1 ms budget and runs under the defaults.
  const Result r3 = twin_bounded("run " + s2.string() + " -o " + out.string() + " --max-duration-s 0.001");
  expect_one_line_failure(r3, "0.001 s (--max-duration-s)");
  const Result r4 = twin_bounded("run " + s2.string() + " -o " + out.string() + " --no-plots");
  EXPECT_EQ(r4.exit_code, 0) << r4.err;
}

TEST(CliHostile, IntegerWordsAndSpindleSpeedRangeChecked) {
  const auto out = test_support::removed(work() / "out");
  const struct {
    const char* dir;
    std::string program;
    const char* what;
  } cases[] = {
      {"g_huge", "G21 G90\nG100000000000000000000 X2\nM30\n", "unknown G code"},
      {"m_huge", "G21 G90\nG1 X1 F100\nM60000000000000000\n", "unknown M code"},
      {"s_huge", "G21 G90\nS100000000000000000000 M3\nG1 X1 F100\nM30\n", "spindle speed"},
      {"s_cut", "G21 G90\nS10000000 M3\nG1 X1 F100\nM30\n", "spindle speed"},
      {"n_frac", "G21 G90\nN1.5 G1 X1 F100\nM30\n", "N must be a whole number"},
      {"t_neg", "G21 G90\nT-3\nG1 X1 F100\nM30\n", "T must be a whole number"},
  };
  for (const auto& c : cases) {
    const Result r = run_program(c.dir, c.program, out);
    expect_one_line_failure(r, std::string(c.dir) + "/program.nc:");
    EXPECT_THAT(r.err, HasSubstr(c.what)) << c.dir;
  }
  expect_no_files(out);
}

TEST(CliHostile, EmptyProgramsRefused) {
  const auto out = work() / "out";
  for (const auto& [dir, text] : std::vector<std::pair<std::string, std::string>>{
           {"empty", ""}, {"percent", "%\n%\n"}, {"settings", "%\nG21 G90 (no motion)\nM30\n%\n"}}) {
    expect_one_line_failure(run_program(dir, text, out), "holds no move");
  }
  expect_no_files(out);
}

TEST(CliHostile, DuplicateAndComplexYamlKeysRefusedWithFileAndLine) {
  const auto out = work() / "out";
  // Scenario: program given twice.
  const auto s1 = scenario_with("dup_scen", "G21 G90\nG1 X1 F100\nM30\n", "start_mm: [0, 0, 0]\nprogram: other.nc\n");
  expect_one_line_failure(twin_bounded("run " + s1.string() + " -o " + out.string()),
                          "dup_scen/scenario.yaml:5: key 'program' appears twice");
  // Machine: the shipped file with a second Kp for x right before the first.
  std::string machine = slurp(std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios/machines/fadal2216.yaml");
  const auto kp = machine.find("    Kp:");
  ASSERT_NE(kp, std::string::npos);
  machine.insert(kp, "    Kp: 1000000\n");
  const auto m = file("dup_machine/m.yaml", machine);
  const auto s2 = scenario_with("dup_machine", "G21 G90\nG1 X1 F100\nM30\n");
  const Result r2 = twin_bounded("run " + s2.string() + " --machine " + m.string() + " -o " + out.string());
  expect_one_line_failure(r2, m.string() + ":");
  EXPECT_THAT(r2.err, HasSubstr("key 'Kp' appears twice"));
  // A complex (list) key: named with file and line, not a bare yaml-cpp "bad conversion".
  const auto s3 = scenario_with("complex", "G21 G90\nG1 X1 F100\nM30\n", "? [a, b]\n: 1\n");
  expect_one_line_failure(twin_bounded("run " + s3.string() + " -o " + out.string()),
                          "complex/scenario.yaml:4: a key must be a plain name");
  // The process section (read by the same loader): a duplicate inside it.
  const auto s4 = scenario_with("dup_process", "G21 G90\nG1 X1 F100\nM30\n",
                                "process:\n  lead_deg: 0\n  lead_deg: 5\n");
  expect_one_line_failure(twin_bounded("run " + s4.string() + " -o " + out.string()),
                          "dup_process/scenario.yaml:6: key 'lead_deg' appears twice");
  // Newlines smuggled into a key or a file name (YAML escapes): still one
  // line, the bytes shown escaped (found by the machine-file fuzzer).
  const auto s5 = scenario_with("nl_key", "G21 G90\nG1 X1 F100\nM30\n", "\"a\\nb\": 1\n");
  expect_one_line_failure(twin_bounded("run " + s5.string() + " -o " + out.string()),
                          "nl_key/scenario.yaml:4: a key must be a plain name, not 'a\\x0ab'");
  // A machine name longer than a file name may be (found by the scenario
  // fuzzer: std::filesystem_error escaped the loader).
  const auto s7 = file("long_machine/scenario.yaml",
                       "name: n\nmachine: " + std::string(300, 'm') + ".yaml\nprogram: p.nc\n");
  expect_one_line_failure(twin_bounded("run " + s7.string() + " -o " + out.string()), "File name too long");
  const auto s6 = file("nl_prog/scenario.yaml", "name: n\nmachine: fadal2216\nprogram: \"p\\n.nc\"\n");
  expect_one_line_failure(twin_bounded("run " + s6.string() + " -o " + out.string()), "single line");
  expect_no_files(out);
}

TEST(CliHostile, OnlyRegularFilesOfBoundedSizeAreRead) {
  const auto out = work() / "out";
  // program: /dev/zero
  const auto s1 = file("zero/scenario.yaml", "name: zero\nmachine: fadal2216\nprogram: /dev/zero\n");
  expect_one_line_failure(twin_bounded("run " + s1.string() + " -o " + out.string()),
                          "/dev/zero: not a regular file");
  // A FIFO as the program: no writer ever comes; the read must not wait.
  const auto fifo = work() / "fifo/program.nc";
  std::filesystem::create_directories(fifo.parent_path());
  std::filesystem::remove(fifo);
  ASSERT_EQ(std::system(("mkfifo " + fifo.string()).c_str()), 0);
  const auto s2 = file("fifo/scenario.yaml", "name: fifo\nmachine: fadal2216\nprogram: program.nc\n");
  expect_one_line_failure(twin_bounded("run " + s2.string() + " -o " + out.string(), 30), "not a regular file");
  // A directory as the machine file.
  const auto dir = work() / "a_dir.yaml";
  std::filesystem::create_directories(dir);
  const auto s3 = scenario_with("dirmachine", "G21 G90\nG1 X1 F100\nM30\n");
  expect_one_line_failure(twin_bounded("run " + s3.string() + " --machine " + dir.string() + " -o " + out.string()),
                          "is a directory");
  // A measured trace that links to /dev/zero.
  file("zerorun/meta.json", R"({"machine": "fadal2216", "controller_period_s": 0.0001})");
  const auto link = work() / "zerorun/trace.csv";
  std::filesystem::remove(link);
  std::filesystem::create_symlink("/dev/zero", link);
  expect_one_line_failure(twin_bounded("replay " + (work() / "zerorun").string() + " -o " + out.string()),
                          "not a regular file");
  // A program over the 256 MB limit: a sparse file costs no disk.
  const auto bigprog = work() / "bigprog/program.nc";
  std::filesystem::create_directories(bigprog.parent_path());
  { std::ofstream(bigprog) << "G1 X1 F100\n"; }
  std::filesystem::resize_file(bigprog, (std::uintmax_t{256} << 20) + 1);
  const auto s5 = file("bigprog/scenario.yaml", "name: big\nmachine: fadal2216\nprogram: program.nc\n");
  expect_one_line_failure(twin_bounded("run " + s5.string() + " -o " + out.string()), "the limit is 256 MB");
  std::filesystem::remove(bigprog);
  expect_no_files(out);
}

TEST(CliHostile, ReplayRefusesAControllerPeriodFarBelowTheSamplePeriod) {
  // meta.json asks for Ts = 1e-9 s under a 1e-4 s trace: 1e5 controller
  // periods per sample. Before: std::bad_alloc; now a message with the figures.
  file("finerun/meta.json", R"({"machine": "fadal2216", "controller_period_s": 1e-9, "sample_period_s": 0.0001})");
  std::string csv = "t_s,x_ref_mm,x_mm\n";
  for (int k = 0; k < 2000; ++k) csv += std::to_string(k * 1e-4) + ",0,0\n";
  file("finerun/trace.csv", csv);
  const auto out = work() / "out";
  const Result r = twin_bounded("replay " + (work() / "finerun").string() + " -o " + out.string());
  expect_one_line_failure(r, "controller periods");
  EXPECT_THAT(r.err, Not(HasSubstr("bad_alloc")));
  expect_no_files(out);
}

TEST(CliHostile, GcodeErrorsQuoteAShortEscapedExcerpt) {
  const auto out = work() / "out";
  // A 1 MB comment never closed, with a control byte and a NUL: the message
  // quotes the line, and stays short.
  std::string line = "G1 X1 F100 (\x01";
  line += std::string(1 << 20, 'A');
  line.push_back('\0');
  line += "tail";
  const auto s = scenario_with("longline", "G21 G90\n" + line + "\nM30\n");
  const Result r = twin_bounded("run " + s.string() + " -o " + out.string());
  expect_one_line_failure(r, "longline/program.nc:2: comment not closed");
  EXPECT_LT(r.err.size(), 400u) << r.err.size() << " bytes";
  EXPECT_THAT(r.err, HasSubstr("..."));
  EXPECT_EQ(r.err.find('\x01'), std::string::npos);
  expect_no_files(out);
}

TEST(CliHostile, IntegratorFailureNamesTheAxisAndTheParameter) {
  const auto s = scenario_with("tinyJ", "G21 G90\nG1 X5 F1000\nM30\n");
  const auto out = work() / "out";
  const Result r = twin_bounded("run " + s.string() + " -o " + out.string() + " --set x.J=1e-12");
  expect_one_line_failure(r, "axis x");
  EXPECT_THAT(r.err, HasSubstr("J = 1e-12"));
  expect_no_files(out);
}

// Progress of long runs on a terminal, never in a pipe. Oracle: the run's
// tick count (a 12 s dwell is 120000 ticks of 1e-4 s, above the 100000 from
// which progress is shown; 1 % of it is 1200 ticks). `script` gives the run a
// terminal; without it (a file) stderr stays empty.
TEST(CliHostile, ProgressOnATerminalOnly) {
  const auto s = scenario_with("dwell12", "G21 G90\nG4 P12\nM30\n");
  const auto out = work() / "out";
  const Result piped = twin_bounded("run " + s.string() + " -o " + out.string() + " --no-plots");
  ASSERT_EQ(piped.exit_code, 0) << piped.err;
  EXPECT_EQ(piped.err, "");
  if (std::system("command -v script >/dev/null 2>&1") != 0) GTEST_SKIP() << "no `script` to give the run a terminal";
  const auto log = work() / "tty.txt";
  const std::string inner = "timeout 120 " + std::string(TWIN_BINARY_DIR) + "/bin/twin run " + s.string() + " -o " +
                            out.string() + " --no-plots";
  const std::string cmd = "script -qec '" + inner + "' /dev/null >" + log.string() + " 2>&1 </dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const std::string tty = slurp(log);
  EXPECT_THAT(tty, HasSubstr("twin run dwell12: "));
  EXPECT_THAT(tty, HasSubstr("% ("));
  EXPECT_THAT(tty, HasSubstr("of 120500 ticks)"));  // 120000 + 500 ticks of settle_s = 0.05 s
  EXPECT_THAT(tty, HasSubstr("cycle time"));
}

}  // namespace
}  // namespace twin
