// The drives and the cutting process coupled every tick, on the default
// FADAL pocket corner (Duan 2025 conditions, Al 2024-T6):
// - energy balance per axis: electrical work at the motor shaft = friction +
//   damping + load (cutting) work + kinetic energy, integrated by the drive;
// - the load work the drives did equals the work of the process's own force
//   along the real tool displacements, sum F_avg . dx (the coupling's sign and
//   scale: Td = F rg / 1000);
// - through the inner corner the engagement and the force rise and the real
//   feed drops below the programmed one.
#include <cmath>
#include <memory>

#include <gtest/gtest.h>

#include "feeddrive/drive_bank.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/sim/scenario.hpp"
#include "twin/sim/cosimulation.hpp"

namespace twin {
namespace {

TEST(Coupling, EnergyBalanceAndCuttingWorkThroughTheCorner) {
  const io::Scenario sc = io::load_scenario(io::default_scenario_path());
  ASSERT_TRUE(sc.process_setup);
  const sim::PlannedProgram planned = sim::plan_program(sc, sc.machine);
  const controller::Program& program = planned.program;
  const auto& ref = planned.reference;
  ASSERT_FALSE(ref->trajectory().corners().empty());
  sim::CoSimulation cs = sim::build_cosimulation(sc, {.reference = ref});

  double process_work_J = 0.0;
  double max_engagement_deg = 0.0, engagement_before_deg = 0.0;
  double max_force_N = 0.0, force_before_N = 0.0;
  double min_feed_ratio = 1e9;
  // The inner (cutting) corner is the one between two G1 blocks.
  double t_corner_s = -1.0;
  for (const auto& c : ref->trajectory().corners())
    if (program.blocks[c.block_before].kind == controller::MotionKind::kLinear &&
        program.blocks[c.block_after].kind == controller::MotionKind::kLinear)
      t_corner_s = c.t_s;
  ASSERT_GT(t_corner_s, 0.0);
  const auto n = static_cast<std::int64_t>((t_corner_s + 0.3) / sc.machine.Ts_s);
  for (std::int64_t k = 0; k < n; ++k) {
    // Row k; after step() the drives stand at t_k+1, so the displacement over
    // the tick is drive_state().x_mm - row.x_true_mm.
    const sim::Snapshot& row = cs.step();
    std::array<double, 3> x_next{};
    for (Axis a : cs.axes()) {
      const auto& st = cs.drive_state(a);
      x_next[index(a)] = st.x_mm;
    }
    for (std::size_t a = 0; a < 3; ++a) {
      process_work_J += row.F_avg_N[a] * (x_next[a] - row.axes[a].x_true_mm) * 1e-3;
    }
    const double F = std::hypot(row.F_avg_N[0], row.F_avg_N[1]);
    if (row.t_s < t_corner_s - 0.5 && row.t_s > t_corner_s - 1.5) {
      engagement_before_deg = std::max(engagement_before_deg, row.engagement_deg);
      force_before_N = std::max(force_before_N, F);
    }
    if (std::abs(row.t_s - t_corner_s) < 0.05) {
      max_engagement_deg = std::max(max_engagement_deg, row.engagement_deg);
      max_force_N = std::max(max_force_N, F);
      if (row.feed_programmed_mm_per_min > 0.0)
        min_feed_ratio = std::min(min_feed_ratio, row.feed_real_mm_per_min / row.feed_programmed_mm_per_min);
    }
  }
  double load_work_J = 0.0;
  for (Axis a : cs.axes()) {
    const feeddrive::DriveState& st = cs.drive_state(a);
    const feeddrive::DriveParams& p = cs.drive_params(a);
    const double stored = feeddrive::kinetic_energy_J(p, st) + feeddrive::spring_energy_J(p, st);
    const double rhs = st.work_friction_J + st.work_damping_J + st.work_load_J + stored;
    // The drive integrates friction and damping work as quadratures to the
    // solver tolerance and the rest exactly: 1e-6 of the electrical work.
    EXPECT_NEAR(st.work_electrical_J, rhs, 1e-6 * std::max(1.0, std::abs(st.work_electrical_J))) << axis_name(a);
    load_work_J += st.work_load_J;
  }
  // Td is held over the tick, so its work is Td * dtheta = F_avg * dx exactly
  // (rounding only).
  EXPECT_GT(process_work_J, 0.0);
  EXPECT_NEAR(load_work_J, process_work_J, 1e-9 + 1e-9 * std::abs(process_work_J));
  // Corner: more material engaged, more force, the real feed dips.
  EXPECT_GT(engagement_before_deg, 40.0);
  EXPECT_GT(max_engagement_deg, engagement_before_deg + 40.0);
  EXPECT_GT(max_force_N, 1.3 * force_before_N);
  EXPECT_LT(min_feed_ratio, 0.5);
}

}  // namespace
}  // namespace twin
