// The Simbody structure model against the closed forms of a stack of
// orthogonal slides: each drive carries the sum of the masses it moves, the
// slides do not couple, gravity loads only Z, with the motor torque
// (m g - F_cb) rg / eta; the screw's torsional stiffness is k rg^2. Orthogonal
// sliders make all of this independent of position, so two configurations are
// checked. Tolerance: round-off of Simbody's O(n) recursions on numbers of
// order 1e3 (1e-12 relative).
#include "twin/structure/machine_structure.hpp"

#include <cmath>

#include <gtest/gtest.h>

#include "twin/core/error.hpp"

namespace twin::structure {
namespace {

constexpr double kRel = 1e-12;

StructureSpec spec_of(Stacking s) {
  return {.stacking = s, .table_kg = 250.0, .saddle_kg = 300.0, .head_kg = 400.0, .workpiece_kg = 35.0,
          .counterbalance_N = 1200.0, .screw_efficiency = 0.9, .screw_stiffness_N_per_um = {150.0, 160.0, 170.0}};
}

const std::array<std::array<double, 3>, 2> kConfigurations{{{0.0, 0.0, 0.0}, {430.0, -215.5, -377.0}}};
const std::array<double, 3> kRg{1.5915, 1.5915, 2.5};

TEST(MachineStructure, MassMatrixIsTheSumOfTheCarriedMassesOnTheDiagonal) {
  for (Stacking s : {Stacking::kXOnY, Stacking::kYOnX}) {
    const StructureSpec sp = spec_of(s);
    const double table = sp.table_kg + sp.workpiece_kg, table_and_saddle = table + sp.saddle_kg;
    // x_on_y: X moves the table (and workpiece), Y the saddle with the table on it.
    const std::array<double, 3> expect = s == Stacking::kXOnY
                                             ? std::array<double, 3>{table, table_and_saddle, sp.head_kg}
                                             : std::array<double, 3>{table_and_saddle, table, sp.head_kg};
    for (const auto& q : kConfigurations) {
      const auto M = mass_matrix(sp, q);
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) {
          const double want = i == j ? expect[static_cast<std::size_t>(i)] : 0.0;
          EXPECT_NEAR(M[static_cast<std::size_t>(3 * i + j)], want, kRel * table_and_saddle)
              << stacking_name(s) << " M(" << i << "," << j << ") at q = " << q[0] << ", " << q[1] << ", " << q[2];
        }
      const auto loads = axis_loads(sp, kRg, q);
      for (int a = 0; a < 3; ++a) {
        const auto ai = static_cast<std::size_t>(a);
        EXPECT_NEAR(loads[ai].carried_kg, expect[ai], kRel * expect[ai]);
        const double rg_m = kRg[ai] / 1000.0;
        EXPECT_NEAR(loads[ai].reflected_J_kg_m2, expect[ai] * rg_m * rg_m, kRel * expect[ai] * rg_m * rg_m);
      }
    }
  }
}

TEST(MachineStructure, GravityIsAConstantTorqueOnZOnly) {
  for (double cb : {0.0, 1200.0}) {
    StructureSpec sp = spec_of(Stacking::kXOnY);
    sp.counterbalance_N = cb;
    const double Fz = sp.head_kg * sp.g_m_per_s2 - cb;
    const double Tz = Fz * kRg[2] / 1000.0 / sp.screw_efficiency;   // m g rg / eta, less the counterbalance
    for (const auto& q : kConfigurations) {
      const auto loads = axis_loads(sp, kRg, q);
      EXPECT_NEAR(loads[2].gravity_force_N, -Fz, kRel * sp.head_kg * sp.g_m_per_s2);
      EXPECT_NEAR(loads[2].gravity_torque_Nm, Tz, kRel * std::abs(Tz) + 1e-15);
      // Horizontal slides: no gravity along them (round-off of g times the masses).
      EXPECT_NEAR(loads[0].gravity_torque_Nm, 0.0, 1e-12);
      EXPECT_NEAR(loads[1].gravity_torque_Nm, 0.0, 1e-12);
    }
  }
}

TEST(MachineStructure, ScrewTorsionalStiffnessIsAxialStiffnessTimesRgSquared) {
  const StructureSpec sp = spec_of(Stacking::kXOnY);
  const auto loads = axis_loads(sp, kRg);
  for (std::size_t a = 0; a < 3; ++a) {
    const double K = sp.screw_stiffness_N_per_um[a] * 1e6 * std::pow(kRg[a] / 1000.0, 2);
    EXPECT_NEAR(loads[a].screw_K_Nm_per_rad, K, kRel * K);
  }
}

TEST(MachineStructure, BadSpecIsAConfigErrorNamingTheField) {
  StructureSpec sp = spec_of(Stacking::kXOnY);
  sp.head_kg = -1.0;
  try {
    static_cast<void>(axis_loads(sp, kRg));
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("head_kg"), std::string::npos) << e.what();
  }
  sp = spec_of(Stacking::kXOnY);
  sp.screw_efficiency = 1.5;
  EXPECT_THROW(static_cast<void>(axis_loads(sp, kRg)), ConfigError);
  sp = spec_of(Stacking::kXOnY);
  EXPECT_THROW(static_cast<void>(axis_loads(sp, {1.0, 0.0, 1.0})), ConfigError);
  EXPECT_FALSE(parse_stacking("z_on_x").has_value());
  EXPECT_EQ(parse_stacking("y_on_x"), Stacking::kYOnX);
}

// The stepped model against uniform acceleration: a constant screw force on
// each slide, x = F t^2 / (2 M_ii) on X and Y, and on Z the net of the force,
// the weight and the counterbalance over the head's mass. 1e-9 relative:
// Runge-Kutta-Merson at accuracy 1e-10 integrates a quadratic exactly up to
// round-off and its error control.
TEST(MachineStructure, SteppedModelAcceleratesTheCarriedMassesUniformly) {
  const StructureSpec sp = spec_of(Stacking::kXOnY);
  const std::array<double, 3> q0{10.0, 20.0, -30.0};
  StructureStepper stepper(sp, q0, 1e-10);
  const std::array<double, 3> F{500.0, -800.0, 4500.0};
  std::array<double, 3> q{};
  for (int k = 0; k < 100; ++k) q = stepper.advance(F, 1e-4);
  const double t = 0.01;
  EXPECT_NEAR(stepper.time_s(), t, 1e-15);
  const std::array<double, 3> m{sp.table_kg + sp.workpiece_kg, sp.table_kg + sp.workpiece_kg + sp.saddle_kg,
                                sp.head_kg};
  const std::array<double, 3> net{F[0], F[1], F[2] - sp.head_kg * sp.g_m_per_s2 + sp.counterbalance_N};
  for (std::size_t a = 0; a < 3; ++a) {
    const double dx_mm = 1000.0 * net[a] * t * t / (2.0 * m[a]);
    EXPECT_NEAR(q[a] - q0[a], dx_mm, 1e-9 * std::abs(dx_mm) + 1e-12) << "axis " << a;
  }
  EXPECT_THROW(static_cast<void>(stepper.advance(F, 0.0)), ConfigError);
}

}  // namespace
}  // namespace twin::structure
