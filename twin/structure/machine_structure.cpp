// Built as C++17 (Simbody 3.7's headers do not compile as C++20 with g++ 12).
#include "twin/structure/machine_structure.hpp"

#include <cmath>
#include <sstream>

#include <Simbody.h>

#include "twin/core/error.hpp"

namespace twin::structure {
namespace {

std::string fmt_value(double v) {
  std::ostringstream o;
  o.precision(10);
  o << v;
  return o.str();
}

void require(bool ok, const std::string& where, const std::string& field, double v, const char* rule) {
  if (!ok) throw ConfigError(where + ": structure." + field + " = " + fmt_value(v) + " " + rule);
}

/// A body of mass m with its centre of mass at com (m, body frame) and the
/// gyration of a brick of the given half sizes: only the mass shows in the
/// sliders' mass matrix, the rest is there so that the bodies are real ones.
SimTK::Body::Rigid brick(double m, const SimTK::Vec3& com, const SimTK::Vec3& half_m) {
  return SimTK::Body::Rigid(SimTK::MassProperties(m, com, SimTK::UnitInertia::brick(half_m).shiftFromCentroid(-com)));
}

/// The slide's frame: its x axis along the machine axis a (0 x, 1 y, 2 z).
SimTK::Rotation along(int a) {
  if (a == 0) return SimTK::Rotation();
  if (a == 1) return SimTK::Rotation(SimTK::Pi / 2, SimTK::ZAxis);
  return SimTK::Rotation(-SimTK::Pi / 2, SimTK::YAxis);
}

/// The Simbody model of a spec, with a state at slide positions q.
struct Model {
  SimTK::MultibodySystem system;
  SimTK::SimbodyMatterSubsystem matter{system};
  SimTK::GeneralForceSubsystem forces{system};
  SimTK::MobilizedBody slide[3];
  std::optional<SimTK::Force::DiscreteForces> discrete;   // the screws' forces (stepper only)
  SimTK::State state;

  Model(const StructureSpec& spec, const std::array<double, 3>& q_mm, bool with_screw_forces = false) {
    using namespace SimTK;
    spec.validate("structure model");
    Force::Gravity(forces, matter, -ZAxis, spec.g_m_per_s2);
    // The base (and the column on it) is the ground: fixed, rigid.
    MobilizedBody& ground = matter.Ground();
    const int lower = spec.stacking == Stacking::kXOnY ? 1 : 0;   // the saddle's axis
    const int upper = 1 - lower;                                   // the table's axis
    // Saddle on the base, table on the saddle, the workpiece welded on the table.
    MobilizedBody::Slider saddle(ground, Transform(along(lower), Vec3(0, 0, 0.30)),
                                 brick(spec.saddle_kg, Vec3(0, 0, 0.08), Vec3(0.30, 0.25, 0.08)),
                                 Transform(along(lower)));
    MobilizedBody::Slider table(saddle, Transform(along(upper), Vec3(0, 0, 0.16)),
                                brick(spec.table_kg, Vec3(0, 0, 0.05), Vec3(0.45, 0.20, 0.05)),
                                Transform(along(upper)));
    if (spec.workpiece_kg > 0.0)
      MobilizedBody::Weld(table, Transform(Vec3(0, 0, 0.10)),
                          brick(spec.workpiece_kg, Vec3(0, 0, 0.05), Vec3(0.10, 0.10, 0.05)), Transform());
    // The head on the column, the column standing behind the table (+y).
    MobilizedBody::Slider head(ground, Transform(along(2), Vec3(0, 0.60, 0.90)),
                               brick(spec.head_kg, Vec3(0, -0.20, 0.25), Vec3(0.20, 0.30, 0.35)),
                               Transform(along(2)));
    slide[upper] = table;
    slide[lower] = saddle;
    slide[2] = head;
    if (spec.counterbalance_N != 0.0) Force::MobilityConstantForce(forces, head, 0, spec.counterbalance_N);
    if (with_screw_forces) discrete.emplace(forces, matter);
    system.realizeTopology();
    state = system.getDefaultState();
    for (int a = 0; a < 3; ++a) slide[a].setOneQ(state, 0, q_mm[static_cast<std::size_t>(a)] / 1000.0);
    system.realize(state, Stage::Dynamics);
  }
  int u_index(int a) const { return static_cast<int>(slide[a].getFirstUIndex(state)); }
};

}  // namespace

struct StructureStepper::Impl {
  Model model;
  SimTK::RungeKuttaMersonIntegrator integrator;
  Impl(const StructureSpec& spec, const std::array<double, 3>& q0_mm, double accuracy)
      : model(spec, q0_mm, true), integrator(model.system) {
    integrator.setAccuracy(accuracy);
    integrator.setAllowInterpolation(false);   // land on every tick's end, the state the next tick starts from
    integrator.initialize(model.state);
  }
};

StructureStepper::StructureStepper(const StructureSpec& spec, const std::array<double, 3>& q0_mm, double accuracy)
    : impl_(std::make_unique<Impl>(spec, q0_mm, accuracy)) {}
StructureStepper::~StructureStepper() = default;

double StructureStepper::time_s() const { return impl_->integrator.getTime(); }

std::array<double, 3> StructureStepper::advance(const std::array<double, 3>& F_N, double dt_s) {
  if (!(std::isfinite(dt_s) && dt_s > 0.0)) throw ConfigError("structure stepper: dt_s = " + fmt_value(dt_s) + " must be > 0");
  Model& m = impl_->model;
  SimTK::State& s = impl_->integrator.updAdvancedState();
  for (int a = 0; a < 3; ++a) m.discrete->setOneMobilityForce(s, m.slide[a], SimTK::MobilizerUIndex(0), F_N[static_cast<std::size_t>(a)]);
  impl_->integrator.reinitialize(SimTK::Stage::Dynamics, false);
  const double t_end = impl_->integrator.getTime() + dt_s;
  while (impl_->integrator.getTime() < t_end) {
    const SimTK::Integrator::SuccessfulStepStatus st = impl_->integrator.stepTo(t_end);
    if (st == SimTK::Integrator::EndOfSimulation || impl_->integrator.isSimulationOver())
      throw ModelError("structure stepper: the integrator stopped at t = " + fmt_value(impl_->integrator.getTime()));
  }
  std::array<double, 3> q{};
  const SimTK::State& out = impl_->integrator.getState();
  for (int a = 0; a < 3; ++a) q[static_cast<std::size_t>(a)] = m.slide[a].getOneQ(out, 0) * 1000.0;
  return q;
}

std::optional<Stacking> parse_stacking(const std::string& name) {
  if (name == "x_on_y") return Stacking::kXOnY;
  if (name == "y_on_x") return Stacking::kYOnX;
  return std::nullopt;
}
const char* stacking_name(Stacking s) { return s == Stacking::kXOnY ? "x_on_y" : "y_on_x"; }

void StructureSpec::validate(const std::string& where) const {
  auto pos = [&](double v, const char* f) { require(std::isfinite(v) && v > 0.0, where, f, v, "must be > 0"); };
  auto nonneg = [&](double v, const std::string& f) {
    require(std::isfinite(v) && v >= 0.0, where, f, v, "must be >= 0");
  };
  pos(table_kg, "table_kg");
  pos(saddle_kg, "saddle_kg");
  pos(head_kg, "head_kg");
  nonneg(workpiece_kg, "workpiece_kg");
  nonneg(counterbalance_N, "counterbalance_N");
  nonneg(g_m_per_s2, "g");
  require(std::isfinite(screw_efficiency) && screw_efficiency > 0.0 && screw_efficiency <= 1.0, where,
          "screw_efficiency", screw_efficiency, "must be in (0, 1]");
  const char* names[3] = {"screw_stiffness.x", "screw_stiffness.y", "screw_stiffness.z"};
  for (int a = 0; a < 3; ++a) nonneg(screw_stiffness_N_per_um[static_cast<std::size_t>(a)], names[a]);
}

std::array<double, 9> mass_matrix(const StructureSpec& spec, const std::array<double, 3>& q_mm) {
  const Model model(spec, q_mm);
  SimTK::Matrix M;
  model.matter.calcM(model.state, M);
  std::array<double, 9> out{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) out[static_cast<std::size_t>(3 * i + j)] = M(model.u_index(i), model.u_index(j));
  return out;
}

std::array<AxisLoad, 3> axis_loads(const StructureSpec& spec, const std::array<double, 3>& rg_mm_per_rad,
                                   const std::array<double, 3>& q_mm) {
  for (int a = 0; a < 3; ++a) {
    const double rg = rg_mm_per_rad[static_cast<std::size_t>(a)];
    if (!(std::isfinite(rg) && rg > 0.0))
      throw ConfigError("structure model: the transmission rg of axis " + std::string(1, "xyz"[a]) + " = " +
                        fmt_value(rg) + " must be > 0");
  }
  const Model model(spec, q_mm);
  SimTK::Matrix M;
  model.matter.calcM(model.state, M);
  // Generalized forces of everything applied (gravity on every body, the
  // counterbalance on the head's slide): J^T F_body + f_mobility.
  SimTK::Vector f;
  model.matter.multiplyBySystemJacobianTranspose(
      model.state, model.system.getRigidBodyForces(model.state, SimTK::Stage::Dynamics), f);
  f += model.system.getMobilityForces(model.state, SimTK::Stage::Dynamics);
  std::array<AxisLoad, 3> out{};
  for (int a = 0; a < 3; ++a) {
    const auto ai = static_cast<std::size_t>(a);
    const int u = model.u_index(a);
    const double rg_m = rg_mm_per_rad[ai] / 1000.0;
    AxisLoad& l = out[ai];
    l.carried_kg = M(u, u);
    l.gravity_force_N = f[u];
    l.gravity_torque_Nm = -f[u] * rg_m / spec.screw_efficiency;
    l.reflected_J_kg_m2 = l.carried_kg * rg_m * rg_m;
    l.screw_K_Nm_per_rad = spec.screw_stiffness_N_per_um[ai] * 1e6 * rg_m * rg_m;
  }
  return out;
}

}  // namespace twin::structure
