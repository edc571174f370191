// A calibration is worth what it predicts: calibrated on one program and
// validated on another (never fitted on), the calibrated machine's low-passed
// u error must be at most half the nominal machine's where an effect was
// added. Truth: the simulator of these tests (written apart from the twin),
// the FADAL X drive perturbed and carrying a constant load the model does not
// have; fitted on its trapezoid program, validated on the x motion of the
// `clean` example (sweeps, circles, short stops: another program). Half is
// the bar; the nominal machine misses the load and the perturbed J,
// B and Coulomb levels, the calibrated one only the noise.
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "truth_sim.hpp"
#include "twin/calibrate/calibrate.hpp"

namespace twin::analysis {
namespace {

std::filesystem::path dir(const std::string& name) {
  return std::filesystem::path(TWIN_BINARY_DIR) / "tests" / "calibrate_runs" / name;
}

TEST(CrossProgram, CalibratedMachinePredictsAnotherProgramAtLeastTwiceAsWell) {
  const auto clean = std::filesystem::path(TWIN_SHARED_DIR) / "data" / "examples" / "clean";
  if (!std::filesystem::exists(clean)) GTEST_SKIP() << "shared/data/examples not present";
  truth::RunSpec spec;
  spec.plant = truth::perturbed_x_plant();
  spec.effects.load_Nm = 0.3;
  truth::write_truth_run(dir("cross_fit"), spec);
  spec.reference_mm = load_run(clean).trace.at("x_ref_mm");
  truth::write_truth_run(dir("cross_validate"), spec);

  const MeasuredRun fit = load_run(dir("cross_fit"));
  const MeasuredRun other = load_run(dir("cross_validate"));
  const sim::MachineDefinition nominal = machine_for_run(fit, "", nullptr);
  const CalibrationResult r = calibrate(fit, nominal);
  ASSERT_FALSE(r.added.empty()) << "an effect must be added for the comparison to apply";

  const AxisErrors before = axis_errors(other, replay_run(other, nominal), Axis::kX, 0);
  const AxisErrors after = axis_errors(other, replay_run(other, r.final_machine), Axis::kX, 0);
  std::printf("  validation u NRMS: nominal %.4f, calibrated %.4f (%s added)\n", before.u, after.u,
              r.added.front().candidate.effect.c_str());
  EXPECT_LE(after.u, 0.5 * before.u);
  EXPECT_LE(after.err_mm, before.err_mm);
}

}  // namespace
}  // namespace twin::analysis
