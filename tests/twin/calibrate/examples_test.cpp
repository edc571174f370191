// The two example runs of shared/data/examples, made by an independent
// simulator with their truth in the READMEs: `clean` has no effect beyond
// the contract's plant, `constant_load_y` a constant load of +0.25 N m on Y.
#include <cmath>
#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>

#include "twin/analysis/calibrate.hpp"
#include "twin/io/machine_file.hpp"

namespace twin::analysis {
namespace {

std::filesystem::path example(const char* name) {
  return std::filesystem::path(TWIN_SHARED_DIR) / "data" / "examples" / name;
}

CalibrationResult run_example(const char* name) {
  const MeasuredRun run = load_run(example(name));
  std::vector<std::string> notes;
  const auto machine = machine_for_run(run, "", &notes);
  CalibrationResult r = calibrate(run, machine);
  std::printf("%s\n", calibration_report_json(r).dump(1).c_str());
  for (const auto& c : r.considered)
    std::printf("considered: %s %s %.3f %.1f: %s\n", c.effect.c_str(), std::string(axis_name(c.axis)).c_str(),
                c.signal_gain, c.t_stat, c.evidence.c_str());
  for (const auto& c : r.rejected) std::printf("rejected: %s %s: %s\n", c.effect.c_str(), std::string(axis_name(c.axis)).c_str(), c.evidence.c_str());
  for (const auto& n : r.notes) std::printf("note: %s\n", n.c_str());
  return r;
}

// Truth (README): X J = 0.00842, B = 0.0156, Tc_pos = 0.232, Tc_neg = 0.207; no effect.
// The identified J must be within 10 % (the S-curves excite inertia well) and
// the Coulomb levels within 0.05 N m (a fifth of their size: stick/slip and the
// quantised position bias the low-speed part); nothing may be added.
TEST(CalibrateExamples, CleanRunAddsNothing) {
  if (!std::filesystem::exists(example("clean"))) GTEST_SKIP() << "shared/data/examples not present";
  const CalibrationResult r = run_example("clean");
  EXPECT_TRUE(r.added.empty());
  const auto& x = r.identification[index(Axis::kX)];
  EXPECT_NEAR(x.J_kg_m2, 0.00842294, 0.1 * 0.00842294);
  EXPECT_NEAR(x.Tc_pos_Nm, 0.232047, 0.05);
  EXPECT_NEAR(x.Tc_neg_Nm, 0.20682, 0.05);
  const auto& y = r.identification[index(Axis::kY)];
  EXPECT_NEAR(y.J_kg_m2, 0.0105476, 0.1 * 0.0105476);
  EXPECT_NEAR(y.B_kg_m2_per_s, 0.352056, 0.1 * 0.352056);
}

// Truth: constant_load on y, +0.25 N m. The torque must be found within
// 0.05 N m (moving, it is read from the Coulomb asymmetry, which carries the
// truth's own asymmetry of 0.025 N m) and no held-out error may be above its
// value before (a constant load with symmetric friction moves the drive as
// the asymmetric levels do; only the stops tell them apart).
TEST(CalibrateExamples, ConstantLoadOnY) {
  if (!std::filesystem::exists(example("constant_load_y"))) GTEST_SKIP() << "shared/data/examples not present";
  const CalibrationResult r = run_example("constant_load_y");
  ASSERT_EQ(r.added.size(), 1u);
  EXPECT_EQ(r.added[0].candidate.effect, "constant_load");
  EXPECT_EQ(r.added[0].candidate.axis, Axis::kY);
  EXPECT_NEAR(r.added[0].candidate.params.at(0).second, 0.25, 0.05);
  for (Axis a : r.axes) {
    EXPECT_LE(r.error_after[index(a)].err_mm, r.error_before[index(a)].err_mm);
    EXPECT_LE(r.error_after[index(a)].u, r.error_before[index(a)].u);
  }
}

}  // namespace
}  // namespace twin::analysis
