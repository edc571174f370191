#pragma once
/// The cuts a program makes, read from its geometry: for each stretch of a
/// feed move, the tool's immersion (entry and exit angle at mid depth), the
/// axial depth, the feed direction, the spindle speed and the feed per tooth.
///
/// The program's moves are walked in order on the scenario's initial stock,
/// the stock is cut as the tool passes (the process model's own height map and
/// sweep), and at every sample (at most `step_mm` apart) the tool circle is
/// probed just outside its radius over the half ahead of the tool:
///   phi in [0, pi], measured clockwise from +y_f, x_f the feed direction,
///   probe point p + (R + cell) (sin phi x_f + cos phi y_f), y_f = x_f turned +90 deg,
/// at mid depth (tip + ap/2). ap is the highest material top on the probed
/// arc above the tip, capped at the flute length. Samples with the same cut
/// (angles to 2 deg, depth to 0.05 mm, speed, feed) are grouped and ranked by
/// the path length they cover.
#include <vector>

#include "controller/gcode.hpp"
#include "process/milling_process.hpp"
#include "process/stability_lobes.hpp"

namespace twin::structure {

struct CutCondition {
  process::Immersion immersion{};
  double ap_mm{0.0};
  double feed_angle_deg{0.0};      ///< feed direction in the machine's xy, deg from +x
  double spindle_rpm{0.0};         ///< signed as programmed (M3 > 0)
  double fz_mm{0.0};               ///< feed per tooth at the programmed feed
  double length_mm{0.0};           ///< path length cut at this condition
  int first_line{0};               ///< program line where it is first seen
};

struct CutStudyOptions {
  double step_mm{0.25};
  double angle_step_deg{1.0};
};

/// The program's cuts, longest first; empty when the tool never engages.
/// Throws ConfigError for a setup the process model refuses.
std::vector<CutCondition> study_cuts(const controller::Program& program, const process::ProcessSetup& setup,
                                     const CutStudyOptions& options = {});

/// The cutting coefficients the zero-order lobes need, linearised for the
/// dynamic chip at the cut's mean chip thickness
///   h_m = fz (cos phi_st - cos phi_ex) / (phi_ex - phi_st):
///   Ktc = d(Kt(h) h)/dh = Kt(h_m) + Kt'(h_m) h_m, likewise Krc; Kr = Krc / Ktc.
struct LinearisedCoefficients {
  double h_mean_mm{0.0};
  double Ktc_N_per_mm2{0.0};
  double Kr_ratio{0.0};
};
LinearisedCoefficients linearise_coefficients(const process::CuttingCoefficients& k, const CutCondition& cut);

}  // namespace twin::structure
