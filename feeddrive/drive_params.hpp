#pragma once
/// Parameters of one feed drive (Ozcan et al. 2017, Fig. 1 and Table 1, after
/// Erkorkmaz): i = Ka u, Tm = Kt i, J dw/dt = Tm - B w - Tf(w) - Td,
/// dx/dt = rg w. Units are those of the FADAL tables.
///
/// DriveEffects holds the optional drive terms of the effect catalogue of
/// spec/measured-data.md. Each is off by default; when on, it is a real term
/// of the drive model (see docs/feeddrive.md for the equations).
#include <string_view>

namespace twin::feeddrive {

/// Friction above the Coulomb level at low speed:
/// Tf(w) = sign(w) (Tc + (Ts_static - Tc) exp(-(w/ws)^2)); breakaway at Ts_static.
struct StribeckEffect {
  bool enabled{false};
  double Ts_static_Nm{0.0};    ///< static (breakaway) friction, > Tc
  double ws_rad_per_s{1.0};    ///< Stribeck speed
};
/// Torque ripple periodic in motor angle theta = x/rg:
/// T_cog = amplitude sin(cycles_per_rev theta + phase), added to the load.
struct CoggingEffect {
  bool enabled{false};
  double amplitude_Nm{0.0};
  double cycles_per_rev{1.0};
  double phase_rad{0.0};
};
/// Ballscrew lead error: the measured position is
/// x_meas = x + amplitude sin(2 pi x / period + phase). Not seen in torque.
struct ScrewPitchErrorEffect {
  bool enabled{false};
  double amplitude_mm{0.0};
  double period_mm{10.0};
  double phase_rad{0.0};
};
/// Lost motion at reversal. Alone: the measured (table) position follows the
/// motor position through a play operator of total width gap_mm (the loop
/// closes on the table, across the gap). With compliance: the gap lies in the
/// coupling, whose spring and damper act only beyond it (the encoder on the
/// motor, the table with its friction picked up at the end of the gap).
struct BacklashEffect {
  bool enabled{false};
  double gap_mm{0.0};
};
/// A constant load torque on the motor shaft (gravity, unbalance, cable),
/// same sign convention as Td (positive opposes motion in +).
struct ConstantLoadEffect {
  bool enabled{false};
  double torque_Nm{0.0};
};
/// Coulomb friction raised by dTc_Nm (both directions) while
/// x_start_mm <= x <= x_end_mm.
struct PositionDependentFrictionEffect {
  bool enabled{false};
  double dTc_Nm{0.0};
  double x_start_mm{0.0};
  double x_end_mm{0.0};
};
/// Pure time delay of the amplifier command, rounded to whole ticks.
struct DelayEffect {
  bool enabled{false};
  double delay_s{0.0};
};
/// Two-mass compliance: the motor (J (1 - load_fraction)) and the load
/// (J load_fraction) joined by a torsional spring K and damper C; the encoder
/// is on the motor. Friction and load torques act on the load side, B on the motor.
struct ComplianceEffect {
  bool enabled{false};
  double K_Nm_per_rad{0.0};
  double C_Nm_s_per_rad{0.0};
  double load_fraction{0.5};
};
/// An undeclared current limit: i = clamp(Ka u, -i_max, i_max).
struct CurrentSaturationEffect {
  bool enabled{false};
  double i_max_A{0.0};
};
/// Friction that holds no torque at rest: the Coulomb level of the direction
/// of motion, smoothed below the speed ws,
///   Tf = Tc_dir(w) tanh(w / ws)        (Tc_dir: Tc_pos for w >= 0, else Tc_neg),
/// in place of stick/slip. The axis never sticks: under a torque T below the
/// Coulomb level it creeps at the speed where Tf + B w = T (w = ws atanh(T / Tc)
/// without B), so a position loop that holds the axis at rest lets its torque
/// relax towards the load. This is how a real drive's friction behaves under
/// the dither of its current loop, or in the pre-sliding range (a ball screw's
/// elastic micro-motion before gross sliding): the torque a stopped axis holds
/// in a real log is spread about zero, not pinned at the breakaway level.
/// Rigid drives only, and not with stribeck (which describes the same
/// low-speed range the other way).
struct SmoothFrictionEffect {
  bool enabled{false};
  double ws_rad_per_s{1.0};
};

/// Friction that rises with speed from a breakaway level below Coulomb: an
/// axis at rest holds only a share of the friction it slides with,
///   Tf(w) = sign(w) Tc_dir (1 - (1 - share) exp(-(w/ws)^2)),
/// breakaway at share Tc_dir (stick/slip as without it). A position loop
/// that stops an axis with its torque near the Coulomb level of the last
/// direction lets it creep on until the torque falls to the breakaway level:
/// the axis holds share Tc_dir in the direction it last moved, not the full
/// Coulomb level (share 1) nor nothing (smooth_friction). Not with stribeck
/// (the same low-speed range the other way) nor with smooth_friction.
struct RisingFrictionEffect {
  bool enabled{false};
  double share{0.5};          ///< breakaway as a share of the Coulomb level, [0, 1)
  double ws_rad_per_s{1.0};   ///< speed over which friction rises to Coulomb
};

/// Friction that rises with the load the drive carries: a ball screw (or a
/// gear) loses a share of the torque it transmits, so its friction grows
/// with the motor's torque,
///   Tf = sign(w) (Tc_dir + fraction |Tm|)
/// (the breakaway level alike). Under a rigid-body model with one inertia
/// the motor then needs more torque to accelerate than the inertia says and
/// less to brake (efficiency below one in both directions of power flow),
/// which one J averages and the velocity loop's integral works off at every
/// acceleration. With compliance the motor's torque stands for the
/// coupling's.
struct LoadDependentFrictionEffect {
  bool enabled{false};
  double fraction{0.05};  ///< friction per unit of |Tm|, [0, 0.5]
};

struct DriveEffects {
  StribeckEffect stribeck;
  CoggingEffect cogging;
  ScrewPitchErrorEffect screw_pitch_error;
  BacklashEffect backlash;
  ConstantLoadEffect constant_load;
  PositionDependentFrictionEffect position_dependent_friction;
  DelayEffect delay;
  ComplianceEffect compliance;
  CurrentSaturationEffect current_saturation;
  SmoothFrictionEffect smooth_friction;
  RisingFrictionEffect rising_friction;
  LoadDependentFrictionEffect load_dependent_friction;
};

struct DriveParams {
  double Ka_A_per_V{0.0};         ///< current amplifier gain
  double Kt_Nm_per_A{0.0};        ///< motor torque constant
  double J_kg_m2{0.0};            ///< inertia reflected to the motor shaft
  double B_kg_m2_per_s{0.0};      ///< viscous damping
  double rg_mm_per_rad{0.0};      ///< transmission (lead / 2 pi)
  double Tc_pos_Nm{0.0};          ///< Coulomb friction moving in +
  double Tc_neg_Nm{0.0};          ///< Coulomb friction moving in - (positive number)
  DriveEffects effects;

  /// Throws ConfigError naming `where`, the field, the value and the limit.
  void validate(std::string_view where) const;
};

}  // namespace twin::feeddrive
