// `twin run` trace options and `twin sweep`, through the program as a user
// runs it. Oracles: a decimated or gzip'd trace against the full-rate plain
// trace of the same run; a sweep case's figures against `twin run` of the same
// case on its own; the MPI sweep's tables against the local sweep's, byte for
// byte (the same cases, the same figures: nothing may depend on who ran what).
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/support/test_files.hpp"
#include "twin/io/trace_csv.hpp"

namespace twin {
namespace {

using ::testing::HasSubstr;

using test_support::slurp;

std::filesystem::path work() {
  return test_support::fresh_dir(std::filesystem::temp_directory_path() / "twin_scale_cli_test" /
                                 test_support::current_test_name());
}

using Result = test_support::CommandResult;

Result sh(const std::filesystem::path& dir, const std::string& command) { return test_support::run_command(dir, command); }

std::string twin() { return test_support::twin_exe(); }

// A 0.33 s air move on the FADAL 2216: a case costs a fraction of a second.
std::filesystem::path short_scenario(const std::filesystem::path& dir) {
  const auto s = dir / "short";
  std::filesystem::create_directories(s);
  std::ofstream(s / "program.nc") << "%\nG21 G90 G17\nG1 X5 Y0 F3000\nG1 X5 Y5\nM30\n%\n";
  std::ofstream(s / "scenario.yaml") << "name: short\nmachine: fadal2216\nprogram: program.nc\n"
                                        "start_mm: [0, 0, 0]\nsettle_s: 0.02\n";
  return s;
}

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

TEST(RunTrace, LogEveryKeepsEveryNthRowAndTheWholeSummary) {
  const auto d = work();
  const auto sc = short_scenario(d);
  ASSERT_EQ(sh(d, twin() + " run " + sc.string() + " -o " + (d / "full").string() + " --no-plots").exit_code, 0);
  const Result r = sh(d, twin() + " run " + sc.string() + " -o " + (d / "dec").string() +
                             " --no-plots --log-every 7 --trace-format csv.gz");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(std::filesystem::exists(d / "dec" / "trace.csv"));
  io::gunzip_file(d / "dec" / "trace.csv.gz", d / "dec.csv");
  const auto full = lines(slurp(d / "full" / "trace.csv"));
  const auto dec = lines(slurp(d / "dec.csv"));
  ASSERT_GT(full.size(), 1000u);
  // Header, then data rows 0, 7, 14, ... of the full-rate trace, character for character.
  ASSERT_EQ(dec.size(), 1 + (full.size() - 1 + 6) / 7);
  EXPECT_EQ(dec[0], full[0]);
  for (std::size_t i = 1; i < dec.size(); ++i) ASSERT_EQ(dec[i], full[1 + (i - 1) * 7]) << "row " << i;
  // The summary takes in every tick whatever is logged: identical but for the trace entry.
  auto a = nlohmann::json::parse(slurp(d / "full" / "summary.json"));
  auto b = nlohmann::json::parse(slurp(d / "dec" / "summary.json"));
  EXPECT_EQ(b["trace"]["log_every_ticks"], 7);
  EXPECT_EQ(b["trace"]["file"], "trace.csv.gz");
  EXPECT_EQ(b["trace"]["rows"], dec.size() - 1);
  a.erase("trace");
  b.erase("trace");
  EXPECT_EQ(a, b);
}

// gnuplot reads no gzip: the plots of a csv.gz run come from a plain copy
// that must not be left in OUT (the manifest lists exactly the result's files).
TEST(RunTrace, GzipRunWithPlotsLeavesOnlyItsResults) {
  const auto d = work();
  const auto sc = short_scenario(d);
  const Result r = sh(d, twin() + " run " + sc.string() + " -o " + (d / "out").string() + " --trace-format csv.gz");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(d / "out")) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  // corner_path.png: the short scenario's program has a corner.
  EXPECT_EQ(names, (std::vector<std::string>{"corner_path.png", "errors.png", "feedrate.png", "manifest.json",
                                             "summary.json", "trace.csv.gz"}));
}

TEST(RunTrace, BadTraceOptionsAreOneLineErrors) {
  const auto d = work();
  for (const std::string bad : {"--log-every 0", "--log-every x", "--trace-format parquet"}) {
    const Result r = sh(d, twin() + " run -o " + (d / "out").string() + " --no-plots " + bad);
    EXPECT_NE(r.exit_code, 0) << bad;
    EXPECT_EQ(lines(r.err).size(), 1u) << bad << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(d / "out" / "trace.csv")) << bad;
  }
}

std::filesystem::path eight_case_sweep(const std::filesystem::path& d) {
  short_scenario(d);
  const auto p = d / "sweep.yaml";
  std::ofstream(p) << "scenario: short\nlog_every: 10\ngrid:\n  set:\n    x.Kp: [300, 600]\n"
                      "    y.Kp: [300, 600]\n    x.Kd: [0.2, 0.4]\n";
  return p;
}

TEST(Sweep, EightCasesLocallyMatchTheirOwnRuns) {
  const auto d = work();
  const auto sweep = eight_case_sweep(d);
  const Result r = sh(d, twin() + " sweep " + sweep.string() + " -o " + (d / "out").string() + " -j 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto csv = lines(slurp(d / "out" / "results.csv"));
  ASSERT_EQ(csv.size(), 9u);
  EXPECT_THAT(csv[0], HasSubstr("case,name,status,error,x.Kp,y.Kp,x.Kd,"));
  const auto j = nlohmann::json::parse(slurp(d / "out" / "results.json"));
  ASSERT_EQ(j["rows"].size(), 8u);
  EXPECT_EQ(j["failed"], 0);
  EXPECT_TRUE(std::filesystem::exists(d / "out" / "summary.png"));
  // Case 5 is x.Kp=600, y.Kp=300, x.Kd=0.4 (first key slowest): the same as a run of its own.
  const auto& row = j["rows"][5];
  EXPECT_EQ(row["x.Kp"], "600");
  EXPECT_EQ(row["y.Kp"], "300");
  EXPECT_EQ(row["x.Kd"], "0.4");
  ASSERT_EQ(sh(d, twin() + " run " + (d / "short").string() + " -o " + (d / "own").string() +
                      " --no-plots --set x.Kp=600 y.Kp=300 x.Kd=0.4")
                .exit_code,
            0);
  const auto own = nlohmann::json::parse(slurp(d / "own" / "summary.json"));
  EXPECT_EQ(row["status"], "ok");
  EXPECT_EQ(row["cycle_time_s"].get<double>(), own["cycle_time_s"].get<double>());
  EXPECT_EQ(row["max_contour_error_mm"].get<double>(), own["max_contour_error_mm"].get<double>());
  EXPECT_EQ(row["max_tracking_error_mm.x"].get<double>(), own["max_tracking_error_mm"]["x"].get<double>());
}

TEST(Sweep, UnderMpiTwoRanksGivesTheLocalTablesByteForByte) {
  const std::string mpiexec = TWIN_MPIEXEC;
  if (mpiexec.empty()) GTEST_SKIP() << "built without MPI";
  const auto d = work();
  const auto sweep = eight_case_sweep(d);
  const Result local = sh(d, twin() + " sweep " + sweep.string() + " -o " + (d / "local").string() + " -j 2");
  ASSERT_EQ(local.exit_code, 0) << local.err;
  // Open MPI refuses root without --allow-run-as-root; --oversubscribe lets 2 ranks share fewer cores.
  const std::string root = ::geteuid() == 0 ? " --allow-run-as-root" : "";
  // Under scripts/sanitize.sh (ASAN_OPTIONS set) the ranks run without
  // LeakSanitizer: Open MPI 4.1 leaves allocations at exit in modules it has
  // already unloaded (LSan prints "<unknown module>": no file a suppression
  // could name). ASan and UBSan stay on in the ranks, and the same sweep code
  // runs leak-checked in the local sweep above.
  std::string env;
  if (const char* asan = std::getenv("ASAN_OPTIONS")) env = "ASAN_OPTIONS='" + std::string(asan) + ":detect_leaks=0' ";
  const Result mpi = sh(d, env + mpiexec + root + " --oversubscribe -np 2 " + twin() + " sweep " + sweep.string() +
                               " -o " + (d / "mpi").string());
  ASSERT_EQ(mpi.exit_code, 0) << mpi.err;
  EXPECT_THAT(slurp(d / "stdout.txt"), HasSubstr("on 2 rank(s)"));
  const std::string csv = slurp(d / "local" / "results.csv");
  ASSERT_FALSE(csv.empty());
  EXPECT_EQ(slurp(d / "mpi" / "results.csv"), csv);
  EXPECT_EQ(slurp(d / "mpi" / "results.json"), slurp(d / "local" / "results.json"));
}

TEST(Sweep, FailingCaseIsReportedAndTheOthersFinish) {
  const auto d = work();
  short_scenario(d);
  const auto p = d / "sweep.yaml";
  std::ofstream(p) << "scenario: short\nlog_every: 10\ncases:\n  - {name: soft, set: [x.Kp=300]}\n"
                      "  - {name: broken, set: [x.Kp=-5]}\n  - {name: stiff, set: [x.Kp=900]}\n";
  const Result r = sh(d, twin() + " sweep " + p.string() + " -o " + (d / "out").string() + " -j 2 --no-plots");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(lines(r.err).size(), 1u) << r.err;
  EXPECT_THAT(r.err, HasSubstr("1 of 3 cases failed"));
  const auto j = nlohmann::json::parse(slurp(d / "out" / "results.json"));
  ASSERT_EQ(j["rows"].size(), 3u);
  EXPECT_EQ(j["rows"][0]["status"], "ok");
  EXPECT_EQ(j["rows"][1]["status"], "failed");
  EXPECT_THAT(j["rows"][1]["error"].get<std::string>(), HasSubstr("Kp"));
  EXPECT_FALSE(j["rows"][1].contains("cycle_time_s"));
  EXPECT_EQ(j["rows"][2]["status"], "ok");
  EXPECT_GT(j["rows"][2]["cycle_time_s"].get<double>(), 0.3);
  EXPECT_EQ(lines(slurp(d / "out" / "results.csv")).size(), 4u);
}

TEST(Sweep, BadSweepFileIsOneLineAndWritesNoTable) {
  const auto d = work();
  const auto p = d / "sweep.yaml";
  std::ofstream(p) << "scenario: short\ngrid:\n  set:\n    Kp: [1]\n";
  const Result r = sh(d, twin() + " sweep " + p.string() + " -o " + (d / "out").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_EQ(lines(r.err).size(), 1u) << r.err;
  EXPECT_THAT(r.err, HasSubstr("sweep.yaml:4"));
  EXPECT_FALSE(std::filesystem::exists(d / "out" / "results.csv"));
}

}  // namespace
}  // namespace twin
