#pragma once
/// The machine's structure as a multibody model (Simbody): the base and the
/// column fixed to the ground, the saddle/table stack and the spindle head on
/// slider mobilizers in the machine's stacking order, the workpiece's mass on
/// the table, gravity along -z and an optional counterbalance on Z.
///
/// From the model at a configuration q (the three slide positions) it gives,
/// per drive: the mass the drive moves (the diagonal of the mass matrix M(q)),
/// the generalized gravity force (J(q)^T of the bodies' weights) and the
/// torque that force puts on the motor through the screw,
///   T_g = -(f_g + F_cb) rg / eta     (positive opposes motion in +),
/// and, where the machine file gives the screw's axial stiffness k, the
/// screw-table mode of the motor J_m against the load J_l = m rg^2 joined by
/// the torsional stiffness K = k rg^2:  w = sqrt(K (1/J_m + 1/J_l)).
///
/// Plain data only: the Simbody types stay in machine_structure.cpp (built as
/// C++17 in its own library), so a caller needs no Simbody headers.
#include <array>
#include <memory>
#include <optional>
#include <string>

namespace twin::structure {

/// Which slide carries which (the table side; the head always rides the column).
enum class Stacking {
  kXOnY,   ///< the table slides in x on the saddle, the saddle in y on the base
  kYOnX,   ///< the table slides in y on the saddle, the saddle in x on the base
};
std::optional<Stacking> parse_stacking(const std::string& name);
const char* stacking_name(Stacking s);

struct StructureSpec {
  Stacking stacking{Stacking::kXOnY};
  double table_kg{0.0};
  double saddle_kg{0.0};
  double head_kg{0.0};            ///< spindle head and everything the Z slide carries
  double workpiece_kg{0.0};       ///< on the table
  double counterbalance_N{0.0};   ///< upward force on the head (0: none)
  double screw_efficiency{1.0};   ///< eta in (0, 1]
  double g_m_per_s2{9.80665};
  /// Screw axial stiffness per axis x, y, z in N/um (0: rigid).
  std::array<double, 3> screw_stiffness_N_per_um{0.0, 0.0, 0.0};

  /// Throws ConfigError naming `where`, the field and the value.
  void validate(const std::string& where) const;
};

/// What one drive sees of the structure.
struct AxisLoad {
  double carried_kg{0.0};          ///< M(q)_ii
  double gravity_force_N{0.0};     ///< generalized gravity force on the slide (+ along the axis)
  double gravity_torque_Nm{0.0};   ///< at the motor, net of the counterbalance; positive opposes +
  double reflected_J_kg_m2{0.0};   ///< carried_kg (rg/1000)^2
  double screw_K_Nm_per_rad{0.0};  ///< k rg^2 (0: rigid screw)
};

/// The structure's loads on the three drives at slide positions q_mm, for
/// transmissions rg_mm_per_rad (x, y, z). Builds and evaluates the Simbody
/// model; throws ConfigError for an invalid spec.
std::array<AxisLoad, 3> axis_loads(const StructureSpec& spec, const std::array<double, 3>& rg_mm_per_rad,
                                   const std::array<double, 3>& q_mm = {0.0, 0.0, 0.0});

/// The full 3x3 mass matrix M(q) in kg (row-major, axes x, y, z).
std::array<double, 9> mass_matrix(const StructureSpec& spec, const std::array<double, 3>& q_mm);

/// The multibody model integrated in time, slide forces in, slide positions
/// out: what stepping Simbody in every co-simulation tick would do. The twin
/// does not run it in the tick (the structure is folded into the drives at
/// load, docs/stability.md "Structure"); it is here to measure that cost
/// (tests/twin/structure/structure_bench.cpp) and to check the dynamics.
class StructureStepper {
 public:
  /// At rest at q0_mm; Runge-Kutta-Merson with the given accuracy.
  StructureStepper(const StructureSpec& spec, const std::array<double, 3>& q0_mm, double accuracy = 1e-8);
  ~StructureStepper();
  StructureStepper(const StructureStepper&) = delete;
  StructureStepper& operator=(const StructureStepper&) = delete;
  /// Advances by dt_s with the screw forces F_N on the slides (x, y, z) held
  /// (gravity and the counterbalance act besides); returns the positions in mm.
  std::array<double, 3> advance(const std::array<double, 3>& F_N, double dt_s);
  double time_s() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace twin::structure
