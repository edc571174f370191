// Every shipped scenario (scenarios/*/scenario.yaml) exported as an FMU and
// run as importers run it (issue 19's acceptance): fmusim-style runs to the
// FMU's own default stop time at output intervals of 1e-4, 1e-3 and 1e-2 s,
// through dlopen, and the independent checker shared/fmi/fmi2check.py with
// its robustness checks, the FMI 2.0 XSD required, on the default
// experiment. Oracles: the FMI 2.0 standard's stepping rules (communication
// points k dt, the last step shortened to the stop time, every step
// fmi2OK, fmi2LastSuccessfulTime equal to the stop time) and a checker that
// is not part of the project.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <unistd.h>

#include "fmu_importer.hpp"
#include "tests/support/test_files.hpp"

namespace twin::fmu_test {
namespace {

namespace fs = std::filesystem;

using test_support::shipped_scenarios;

class ShippedScenarioFmu : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    // One folder per test and process: ctest runs this suite's tests of one
    // scenario side by side, and one's SetUp must not remove the other's FMU.
    const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    dir_ = fs::temp_directory_path() / "twin_fmu_shipped_test" /
           (GetParam() + "_" + test.substr(0, test.find('/')) + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    fmu_path_ = (dir_ / (GetParam() + ".fmu")).string();
    std::string out;
    const int rc = run(std::string(TWIN_BINARY_DIR) + "/bin/twin export-fmu --scenario " + TWIN_SOURCE_DIR +
                           "/scenarios/" + GetParam() + "/scenario.yaml -o " + fmu_path_,
                       out);
    ASSERT_EQ(rc, 0) << out;
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
  std::string fmu_path_;
};

TEST_P(ShippedScenarioFmu, FmusimStyleRunsReachTheDefaultStopTime) {
  LoadedFmu fmu(fmu_path_);
  const auto& f = fmu.fn();
  const double stop = std::stod(fmu.default_experiment("stopTime"));
  ASSERT_GT(stop, 0.0);
  for (double dt : {1e-4, 1e-3, 1e-2}) {
    fmi2Component c = fmu.instantiate("shipped");
    ASSERT_NE(c, nullptr) << (fmu.log().empty() ? "" : fmu.log().back());
    ASSERT_EQ(f.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop), fmi2OK);
    ASSERT_EQ(f.fmi2EnterInitializationMode(c), fmi2OK);
    ASSERT_EQ(f.fmi2ExitInitializationMode(c), fmi2OK);
    double t = 0.0;
    std::int64_t steps = 0;
    bool ok = true;
    for (std::int64_t k = 1; ok && t < stop && std::abs(t - stop) > 1e-9 * stop; ++k) {
      double t_next = static_cast<double>(k) * dt;
      if (t_next > stop || std::abs(t_next - stop) <= 1e-9 * stop) t_next = stop;
      const fmi2Status s = f.fmi2DoStep(c, t, t_next - t, fmi2True);
      ok = s == fmi2OK;
      EXPECT_EQ(s, fmi2OK) << "dt = " << dt << ", t = " << t << ": " << (fmu.log().empty() ? "" : fmu.log().back());
      t = t_next;
      ++steps;
    }
    fmi2Real last = -1.0;
    EXPECT_EQ(f.fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &last), fmi2OK);
    EXPECT_EQ(last, stop) << "dt = " << dt;
    EXPECT_EQ(steps, static_cast<std::int64_t>(std::ceil(stop / dt - 1e-9))) << "dt = " << dt;
    EXPECT_EQ(f.fmi2Terminate(c), fmi2OK);
    f.fmi2FreeInstance(c);
  }
}

TEST_P(ShippedScenarioFmu, IndependentCheckerPassesOnTheDefaultExperiment) {
  // The checker's own limit per forked check is 30 s; 300 s leaves room for
  // the sanitizer build (the checks take well under a second here).
  std::string out;
  const int rc = run(python3() + TWIN_SHARED_DIR "/fmi/fmi2check.py " + fmu_path_ +
                         " --robustness --require-xsd --timeout 300 -q --out " + (dir_ / "checker_out.csv").string(),
                     out);
  EXPECT_EQ(rc, 0) << out;
}

INSTANTIATE_TEST_SUITE_P(Scenarios, ShippedScenarioFmu, ::testing::ValuesIn(shipped_scenarios()),
                         [](const ::testing::TestParamInfo<std::string>& i) { return i.param; });

}  // namespace
}  // namespace twin::fmu_test
