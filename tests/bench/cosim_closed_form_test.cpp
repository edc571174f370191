// The default run with the drives' closed-form ordinary ticks against the
// same run with SUNDIALS on every tick (IntegratorOptions::exact_linear_ticks
// off, the arrangement before the closed form), side by side, tick by tick.
//
// Oracle: the SUNDIALS run, the integrator of record. Tolerance 1e-9 mm on
// every axis position at every tick (the bound the issue sets for the default
// run's results), over the whole default program, air cut and coupled with
// the cutting forces (which close a second loop through the positions).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include "twin/io/scenario_file.hpp"
#include "twin/sim/scenario.hpp"
#include "twin/sim/cosimulation.hpp"

namespace twin {
namespace {

struct Deviation {
  double max_x_mm{0.0};
  double max_contour_mm{0.0};
};

Deviation run_side_by_side(bool coupled) {
  const io::Scenario sc = io::load_scenario(io::default_scenario_path());
  const sim::PlannedProgram planned = sim::plan_program(sc, sc.machine);
  const std::int64_t ticks = sim::run_ticks(sc, planned.trajectory());
  feeddrive::IntegratorOptions every_tick;
  every_tick.exact_linear_ticks = false;
  sim::CoSimulation fast = sim::build_cosimulation(sc, {.reference = planned.reference, .air_cut = !coupled});
  sim::CoSimulation slow =
      sim::build_cosimulation(sc, {.reference = planned.reference, .air_cut = !coupled, .integrator = every_tick});
  Deviation d;
  for (std::int64_t k = 0; k < ticks; ++k) {
    const sim::Snapshot& a = fast.step();
    const sim::Snapshot& b = slow.step();
    for (std::size_t c = 0; c < 3; ++c)
      d.max_x_mm = std::max(d.max_x_mm, std::abs(a.axes[c].x_true_mm - b.axes[c].x_true_mm));
    d.max_contour_mm = std::max(d.max_contour_mm, std::abs(a.contour_error_mm - b.contour_error_mm));
  }
  return d;
}

/// Both runs' positions and contour errors within 1e-9 mm of each other (printed for the record).
void expect_within_1e9_mm_of_sundials(bool coupled, const char* what) {
  const Deviation d = run_side_by_side(coupled);
  EXPECT_LT(d.max_x_mm, 1e-9);
  EXPECT_LT(d.max_contour_mm, 1e-9);
  std::printf("%s: max |x_closed_form - x_sundials| = %.3g mm, contour error %.3g mm\n", what, d.max_x_mm,
              d.max_contour_mm);
}

TEST(CosimClosedForm, DefaultAirCutPositionsWithin1e9mmOfSundials) {
  expect_within_1e9_mm_of_sundials(false, "air cut");
}

TEST(CosimClosedForm, DefaultCoupledPositionsWithin1e9mmOfSundials) {
  expect_within_1e9_mm_of_sundials(true, "coupled");
}

}  // namespace
}  // namespace twin
