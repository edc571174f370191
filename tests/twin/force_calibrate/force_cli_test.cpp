// `twin calibrate SERIES -o OUT` on force logs as a user meets it: the
// outputs, the YAML files `twin cut` reads as they are (with the runout),
// and a bad field as one line naming it with no file left at a final name.
// The series is made by the tests' independent generator (runout 10 um).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/process/force_truth_generator.hpp"
#include "tests/support/test_files.hpp"
#include "twin/io/process_yaml.hpp"

namespace twin {
namespace {

using test_support::slurp;

std::filesystem::path work() {
  return test_support::fresh_dir(std::filesystem::path(TWIN_BINARY_DIR) / "tests" / "force_cli" /
                                 test_support::current_test_name());
}

using Result = test_support::CommandResult;

Result twin_cmd(const std::filesystem::path& dir, const std::string& args) {
  return test_support::run_command(dir, test_support::twin_exe() + " " + args);
}

process::truth::TruthSeries small_series() {
  process::truth::TruthSeries s;
  s.fz_mm = {0.04, 0.08, 0.12};
  s.duration_s = 0.3;
  s.rho_mm = 0.010;
  s.lambda_deg = 60.0;
  return s;
}

TEST(ForceCli, CalibrateWritesFilesTwinCutReads) {
  const auto dir = work();
  process::truth::write_truth_series(dir / "series", small_series());
  const auto out = dir / "out";
  const Result r = twin_cmd(dir, "calibrate " + (dir / "series").string() + " -o " + out.string() + " --no-plots");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"report.json", "report.md", "material.yaml", "tool.yaml"})
    EXPECT_TRUE(std::filesystem::exists(out / f)) << f;
  const auto j = nlohmann::json::parse(slurp(out / "report.json"));
  const auto& cut = j.at("parameters_identified").at("cut");
  for (const char* k : {"Ktc", "Krc", "Kac", "Kte", "Kre", "Kae", "runout_rho_mm", "runout_lambda_deg"})
    EXPECT_TRUE(cut.contains(k)) << k;
  ASSERT_EQ(j.at("effects_added").size(), 1u);
  EXPECT_EQ(j["effects_added"][0]["effect"], "runout");
  EXPECT_TRUE(j["effects_added"][0]["axis"].is_null());
  for (const char* a : {"fx_N", "fy_N", "fz_N"}) {
    EXPECT_TRUE(j.at("error_before").contains(a));
    EXPECT_LE(j["error_after"][a].get<double>(), j["error_before"][a].get<double>());
  }
  // The files load through the twin's own readers with the identified values
  // (written to 6 significant digits).
  const auto k = io::load_material_file(out / "material.yaml", 0.0, 0.0);
  EXPECT_NEAR(k.Kt.a_N_per_mm2, cut["Ktc"].get<double>(), 1e-5 * cut["Ktc"].get<double>());
  EXPECT_NEAR(k.Kre_N_per_mm, cut["Kre"].get<double>(), 1e-5 * cut["Kre"].get<double>());
  const auto tool = io::load_tool_file(out / "tool.yaml");
  EXPECT_NEAR(tool.runout_rho_mm, cut["runout_rho_mm"].get<double>(), 1e-8);
  EXPECT_NEAR(tool.runout_rho_mm, 0.010, 0.001);   // the generator's runout
  // twin cut reads them as they are, runout included: its peaks differ from
  // the same cut with the runout set to 0 on the command line.
  const std::string cut_args = "cut --tool " + (out / "tool.yaml").string() + " --material " +
                               (out / "material.yaml").string() + " --rpm 6000 --fz 0.04 --ae 10 --ap 2";
  const Result with = twin_cmd(dir, cut_args);
  ASSERT_EQ(with.exit_code, 0) << with.err;
  const Result without = twin_cmd(dir, cut_args + " --runout-rho 0");
  ASSERT_EQ(without.exit_code, 0) << without.err;
  EXPECT_NE(with.out, without.out);
}

TEST(ForceCli, MissingCutFieldIsOneLineAndNoFiles) {
  const auto dir = work();
  auto s = small_series();
  s.fz_mm = {0.05};
  s.duration_s = 0.1;
  process::truth::write_truth_series(dir / "series", s);
  const auto meta = dir / "series" / "fz0.050" / "meta.json";
  std::string text = slurp(meta);
  const auto at = text.find("\"feed_mm_per_min\"");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, 17, "\"feed_mm_per_mn\"");
  std::ofstream(meta) << text;
  const auto out = dir / "out";
  const Result r = twin_cmd(dir, "calibrate " + (dir / "series").string() + " -o " + out.string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("cut.feed_mm_per_min"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out / "report.json"));
}

}  // namespace
}  // namespace twin
