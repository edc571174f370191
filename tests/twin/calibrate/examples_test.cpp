// The two example runs of shared/data/examples, made by an independent
// simulator with their truth in the READMEs: `clean` has no effect beyond
// the contract's plant, `constant_load_y` a constant load of +0.25 N m on Y.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "twin/calibrate/calibrate.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/trace_csv.hpp"
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

// The load of `constant_load_y` (+0.25 N m on y) as the only effect, its
// torque within `tol_Nm`, and no held-out error above before.
void expect_only_the_load_on_y(const CalibrationResult& r, double tol_Nm) {
  ASSERT_EQ(r.added.size(), 1u);
  EXPECT_EQ(r.added[0].candidate.effect, "constant_load");
  EXPECT_EQ(r.added[0].candidate.axis, Axis::kY);
  EXPECT_NEAR(r.added[0].candidate.params.at(0).second, 0.25, tol_Nm);
  for (Axis a : r.axes) {
    EXPECT_LE(r.error_after[index(a)].err_mm, r.error_before[index(a)].err_mm);
    EXPECT_LE(r.error_after[index(a)].u, r.error_before[index(a)].u);
  }
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
  expect_only_the_load_on_y(r, 0.05);
}

// The example run as a CNC's own trace would log it: every `step`-th row,
// only the columns named, with the meta.json given.
MeasuredRun logged_copy(const char* name, std::size_t step, const std::vector<std::string>& columns,
                        const std::string& meta_json, const std::string& folder) {
  const MeasuredRun full = load_run(example(name));
  const auto dir = std::filesystem::path(TWIN_BINARY_DIR) / "tests" / "calibrate_runs" / folder;
  std::filesystem::create_directories(dir);
  io::TraceWriter w(dir / "trace.csv", columns);
  std::vector<double> row(columns.size());
  for (std::size_t k = 0; k < full.trace.num_rows(); k += step) {
    for (std::size_t c = 0; c < columns.size(); ++c) row[c] = full.trace.at(columns[c])[k];
    w.write_row(row);
  }
  w.commit();
  io::write_file_atomic(dir / "meta.json", meta_json);
  return load_run(dir);
}

CalibrationResult calibrate_logged(const MeasuredRun& run) {
  std::vector<std::string> notes;
  const auto machine = machine_for_run(run, "", &notes);
  CalibrationResult r = calibrate(run, machine);
  r.notes.insert(r.notes.begin(), notes.begin(), notes.end());
  for (const auto& n : r.notes) std::printf("note: %s\n", n.c_str());
  for (const auto& a : r.added)
    std::printf("added: %s %s: %s\n", a.candidate.effect.c_str(), std::string(axis_name(a.candidate.axis)).c_str(),
                a.candidate.evidence.c_str());
  return r;
}

const std::vector<std::string> kCurrentOnly{"t_s", "x_ref_mm", "x_mm", "x_i_A", "y_ref_mm", "y_mm", "y_i_A"};

// Both examples logged at 1 ms with position and current only, as a CNC's
// servo trace would give them. At 1 ms the current samples the 20 A
// encoder-count chatter; at the 500 mm/min moves its pattern repeats every
// 6 loop ticks and a 10-tick log sees 3 of its phases, which put the mean
// current off by several amperes (docs/calibration.md). Checked: nothing
// added on `clean`; on `constant_load_y` exactly the load on y, its torque
// within 0.12 N m of the truth's 0.25 (at 1 ms the Coulomb levels it is read
// from are known to 0.06 to 0.09 N m each, and are weighted with the
// machine's nominal ones, which pulls the asymmetry toward theirs); no
// held-out error above before; X's inertia within 10 % of the truth.
TEST(CalibrateExamples, OneMillisecondLogsOfCurrentOnly) {
  if (!std::filesystem::exists(example("clean"))) GTEST_SKIP() << "shared/data/examples not present";
  const std::string meta =
      R"({"machine": "fadal2216", "axes": ["x", "y"], "controller_period_s": 0.0001, "sample_period_s": 0.001, )"
      R"("encoder_resolution_mm": 0.001, "description": "1 ms log"})";
  {
    const CalibrationResult r = calibrate_logged(logged_copy("clean", 10, kCurrentOnly, meta, "clean_1ms"));
    EXPECT_TRUE(r.added.empty());
    EXPECT_NEAR(r.identification[index(Axis::kX)].J_kg_m2, 0.00842294, 0.1 * 0.00842294);
  }
  const CalibrationResult r = calibrate_logged(logged_copy("constant_load_y", 10, kCurrentOnly, meta, "load_1ms"));
  expect_only_the_load_on_y(r, 0.12);
}

// `constant_load_y` logged every 10 ms, position and current only, by a
// machine the meta does not name, with no controller period or encoder
// resolution. Checked: calibrate says it assumed the shipped definition; it
// adds nothing but possibly the true load (at 10 ms the Coulomb levels carry
// standard errors of 0.2 to 0.3 N m, as large as the load); the replay of the
// identified model follows the run's tracking error better than no model
// (held-out NRMS below 1: with a straight line between the 10 ms samples of
// the reference it was 2.7 on x); J within 30 % of the truth (the S-curves'
// 25 ms jerk phases span two or three samples) and Coulomb levels within
// 0.1 N m (the data alone gave -0.05 to 0.47 N m; weighted with the nominal
// levels they come within the nominal's own distance from the truth).
TEST(CalibrateExamples, TenMillisecondLogOfAnUnnamedMachine) {
  if (!std::filesystem::exists(example("constant_load_y"))) GTEST_SKIP() << "shared/data/examples not present";
  const std::string meta =
      R"({"machine": null, "axes": ["x", "y"], "controller_period_s": null, "sample_period_s": 0.01, )"
      R"("encoder_resolution_mm": null, "description": "10 ms log"})";
  const CalibrationResult r = calibrate_logged(logged_copy("constant_load_y", 100, kCurrentOnly, meta, "load_10ms"));
  ASSERT_FALSE(r.notes.empty());
  EXPECT_NE(r.notes[0].find("names no machine: the fadal2216 definition is assumed"), std::string::npos);
  for (const auto& a : r.added) {
    EXPECT_EQ(a.candidate.effect, "constant_load");
    EXPECT_EQ(a.candidate.axis, Axis::kY);
  }
  struct Truth {
    Axis axis;
    double J, Tc_pos, Tc_neg;
  };
  for (const Truth& t : {Truth{Axis::kX, 0.0083712, 0.187716, 0.160888}, Truth{Axis::kY, 0.0101833, 0.268798, 0.244034}}) {
    const auto& id = r.identification[index(t.axis)];
    EXPECT_NEAR(id.J_kg_m2, t.J, 0.3 * t.J);
    EXPECT_NEAR(id.Tc_pos_Nm, t.Tc_pos, 0.1);
    EXPECT_NEAR(id.Tc_neg_Nm, t.Tc_neg, 0.1);
    EXPECT_LT(r.error_before[index(t.axis)].err_mm, 1.0);
  }
}

}  // namespace
}  // namespace twin::analysis
