#pragma once
/// End-mill geometry and radial runout.
///
/// The tool is a body of revolution about its axis (machine +z), tip at z = 0.
/// Its cutting-edge profile in the meridian plane, with R = diameter/2 and
/// corner radius r (flat: r = 0, bull-nose: 0 < r < R, ball: r = R):
///   0 <= z <= r:  radius(z) = R - r + sqrt(r^2 - (r - z)^2),  kappa(z) = acos(1 - z/r)
///   z > r:        radius(z) = R,                              kappa(z) = 90 deg
/// kappa is the axial immersion angle between the tool axis and the edge
/// normal (Altintas, Manufacturing Automation, ch. 2.6; Duan 2025 eq. (4)-(7)).
/// Helix: flute j lags by z tan(helix)/R (constant lead).
/// Runout: the tool axis sits rho_mm off the spindle axis in the direction
/// lambda_deg of the rotating tool frame (measured from flute 0's tip, in the
/// direction of rotation). The flute point at height z sits at the frame angle
/// j 2 pi/N - z tan(helix)/R, so its radius follows the flute along z:
///   R_j(z) = R + rho cos(lambda - j 2 pi/N + z tan(helix)/R).
#include <string>

namespace twin::process {

enum class ToolShape { kFlat, kBullNose, kBall };

/// "flat", "bull_nose", "ball"; nullopt-free: throws ConfigError on any other name.
ToolShape parse_tool_shape(const std::string& name, const std::string& where);
const char* tool_shape_name(ToolShape shape);

struct ToolGeometry {
  std::string name{"tool"};
  ToolShape shape{ToolShape::kFlat};
  double diameter_mm{10.0};
  int flutes{2};
  double helix_deg{30.0};
  double corner_radius_mm{0.0};     ///< 0 flat, (0, R) bull-nose, R ball
  double flute_length_mm{20.0};
  double runout_rho_mm{0.0};        ///< radial offset of the tool axis
  double runout_lambda_deg{0.0};    ///< its direction in the rotating frame, from flute 0's tip in the sense of phi

  /// Throws ConfigError naming `where` and the field when a value is out of range
  /// (diameter > 0, 1 <= flutes <= 16, 0 <= helix < 60 deg, corner radius by shape,
  /// flute length > 0, 0 <= rho < R/10).
  void validate(const std::string& where) const;
  double radius_mm() const { return 0.5 * diameter_mm; }
  /// Edge radius (mm) at height z_mm above the tip.
  double edge_radius_mm(double z_mm) const;
  /// Axial immersion angle kappa (rad) at height z_mm above the tip.
  double kappa_rad(double z_mm) const;
  /// Depth (mm above the tip) the tool bottom reaches at distance d_mm from its axis;
  /// > flute_length_mm outside the tool (d > R).
  double bottom_height_mm(double d_mm) const;
  /// Radius (mm) of flute j at height z_mm above the tip, measured from the
  /// spindle axis (runout included), for a flute on the cylinder (radius R).
  double flute_radius_mm(int j, double z_mm) const;
};

}  // namespace twin::process
