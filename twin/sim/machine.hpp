#pragma once
/// A machine definition: per axis the drive (Ozcan 2017 Table 1), the position
/// loop gains (Table 3), the interpolator limits and the travel; machine-wide
/// the position-loop period and the encoder resolution. Every parameter has a
/// name (spec/interfaces.md) through which files, `--set`, the FMU and the
/// reports reach it.
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "controller/interpolator.hpp"
#include "controller/position_loop.hpp"
#include "feeddrive/drive_params.hpp"
#include "process/stability_lobes.hpp"
#include "twin/core/axis.hpp"

namespace twin::sim {

struct AxisDefinition {
  bool present{false};
  feeddrive::DriveParams drive;
  controller::PositionLoopParams loop;  ///< runs at MachineDefinition::Ts_s
  double v_max_mm_per_s{10160.0 / 60.0};
  double a_max_mm_per_s2{2000.0};
  double j_max_mm_per_s3{50000.0};
  double travel_min_mm{-1e9};
  double travel_max_mm{1e9};
  /// A real CNC's following-error alarm: a tracking error beyond this stops
  /// the run as unstable (or mis-tuned) and says where.
  double following_error_limit_mm{1.0};
  /// The sign a measured run logs the axis's torque, current or amplifier
  /// command with, against the twin's (which accelerates the axis in + when
  /// positive): -1 where the log counts it the other way (a motor mounted
  /// the other way round, a drive's direction parameter). The replays of
  /// measured runs on a machine identified from data (calibrate, `twin replay
  /// --machine`) give those channels with it; the simulation does not use it.
  double logged_torque_sign{1.0};
  /// Cascade: 1 where a measured run logs the torque (or current) the
  /// velocity loop commands, before the current loop's lag and any delay (as
  /// many drives trace it), 0 where it logs the motor's. The replays of
  /// measured runs give that channel so; the simulation does not use it.
  double torque_command_logged{0.0};
  /// Cascade: > 0 (s) where a measured run logs the torque (or current)
  /// through a first-order low-pass of this time constant that the loop
  /// does not see (a drive's smoothed torque monitor): the replays of
  /// measured runs give that channel so; the simulation does not use it.
  double logged_torque_filter_s{0.0};
  /// Cascade: 1 where a measured run logs, at each row, the mean of the
  /// torque (or current) over the position-loop period before it, over the
  /// velocity loop's ticks in it (a drive that averages what it traces);
  /// 0 where it logs the value at the row's tick. The replays of measured
  /// runs give that channel so; the simulation does not use it.
  double logged_torque_period_mean{0.0};
};

/// The machine's structure (`structure:` in a machine file): masses, stacking,
/// counterbalance, screw efficiency and stiffness. Plain data: the multibody
/// model that turns it into per-drive numbers lives in twin/structure (Simbody)
/// and is evaluated when the file is loaded (twin/io), which folds the result
/// into the drives: J += carried_kg (rg/1000)^2, the gravity torque as a
/// constant load, a screw stiffness as the two-mass compliance. The drives, the
/// co-simulation and the FMU then see ordinary drive parameters.
struct StructureDefinition {
  std::string stacking{"x_on_y"};     ///< x_on_y: table on the saddle in x, saddle on the base in y
  double table_kg{0.0};
  double saddle_kg{0.0};
  double head_kg{0.0};
  double workpiece_kg{0.0};
  double counterbalance_N{0.0};
  double screw_efficiency{1.0};
  AxisArray<double> screw_stiffness_N_per_um{};   ///< axial, per axis (0: rigid)
  std::string source;                  ///< where the figures come from
  /// What the load folded into each drive (to write the file back unfolded).
  AxisArray<double> carried_kg{};
  AxisArray<double> reflected_J_kg_m2{};
  AxisArray<double> gravity_torque_Nm{};
  AxisArray<bool> enabled_constant_load{};
  AxisArray<bool> enabled_compliance{};
};

struct MachineDefinition {
  std::string name;
  std::string source;                  ///< file it was read from (for messages)
  double Ts_s{1e-4};
  double encoder_resolution_mm{0.001};
  double rapid_mm_per_min{10160.0};
  double blend_tolerance_mm{0.01};     ///< G64 without P
  AxisArray<AxisDefinition> axes;
  /// The tool tip's modes in x and y (`tool_tip:` in a machine file; empty:
  /// rigid). Used by the stability lobes.
  process::ToolTipFrf tool_tip;
  std::string tool_tip_source;         ///< where the modes come from (measured, assumed ...)
  /// The structure (absent: rigid drives with the file's J, the default).
  std::optional<StructureDefinition> structure;

  /// Throws ConfigError naming the source, the axis, the key and the value.
  void validate() const;
  controller::MotionLimits motion_limits() const;
  std::vector<Axis> present_axes() const;
};

/// One named numeric parameter of an axis, as in spec/interfaces.md.
struct AxisParamSpec {
  std::string_view name;   ///< "J", "Kp", "stribeck.Ts_static" ...
  std::string_view unit;
  std::string_view doc;
  double& (*ref)(AxisDefinition&);
  /// For effect parameters: the flag that setting the parameter switches on.
  bool* (*enables)(AxisDefinition&){nullptr};
  /// For loop gains: the law they belong to (the other law's gains are not
  /// written to, nor read from, a machine file of this law).
  std::optional<controller::LoopLaw> law{};
};
struct MachineParamSpec {
  std::string_view name;   ///< "Ts", "encoder_resolution" ...
  std::string_view unit;
  std::string_view doc;
  double& (*ref)(MachineDefinition&);
};

const std::vector<AxisParamSpec>& axis_param_specs();
const std::vector<MachineParamSpec>& machine_param_specs();
const AxisParamSpec* find_axis_param(std::string_view name);
const MachineParamSpec* find_machine_param(std::string_view name);

double get_axis_param(const AxisDefinition& axis, const AxisParamSpec& spec);
void set_axis_param(AxisDefinition& axis, const AxisParamSpec& spec, double value);

/// The loop law of the machine's axes (all axes share one; fadal when none is present).
controller::LoopLaw machine_loop_law(const MachineDefinition& m);
/// Sets the loop law of every axis.
void set_machine_loop_law(MachineDefinition& m, controller::LoopLaw law);

/// Applies one `--set <axis>.<name>=<value>` (or `<name>=<value>` for a
/// machine-wide parameter). Throws ConfigError for an unknown axis or name,
/// a malformed or non-finite value. The caller validates the machine after.
void apply_set(MachineDefinition& machine, std::string_view assignment);

}  // namespace twin::sim
