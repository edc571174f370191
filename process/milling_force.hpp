#pragma once
/// The mechanistic milling-force model (Altintas, Manufacturing Automation,
/// ch. 2; Duan et al. 2025 eqs. (1), (3)-(7)).
///
/// The cutting edge is cut into elements: the corner arc (0 <= z <= r) in
/// equal steps of its angle kappa, r dkappa <= dz, so each element's chip
/// width is db = r dkappa exactly; the flank above in axial disks of height
/// dz (db = dz). The element at the stock top is cut there: it contributes
/// the part of its width below the top (in kappa on the corner, in z on the
/// flank), so the engaged edge length is exact for any depth of cut.
/// Flute j's immersion at z, phi measured clockwise from +y, spindle
/// clockwise seen from above (M3):
///   phi_j(z) = phi + j 2 pi/N - z tan(helix)/R
/// Its edge point sits at p + R_j(z) (sin phi_j, cos phi_j). Radial chip, with
/// the feed per tooth as a vector f = v_xy/(N n) from the tool's actual
/// velocity and runout radii R_j(z) = R + rho cos(lambda - j 2 pi/N + z tan(helix)/R)
/// that follow the flute along z (Kline-DeVor: the chip is left by the
/// nearest of the previous m flutes, compared at the same height):
///   h_r = min_{m=1..N} ( m f . (sin phi_j, cos phi_j) + R_j(z) - R_{j-m}(z) )
/// Chip with lead angle thetaL (Duan eq. (4)), kappa the axial immersion:
///   h = h_r cos(thetaL) sin(kappa) - |f| sin(thetaL) cos(kappa)
/// An element cuts when h > 0 and its edge point (pushed out by probe_mm, see
/// below) lies in remaining material. Its forces, chip width db:
///   dFt = (Kt(h) h + Kte) db, dFr = (Kr(h) h + Kre) db, dFa = (Ka(h) h + Kae) db
/// On the tool, in machine axes:
///   Fx = -dFt cos phi - dFr sin kappa sin phi + dFa cos kappa sin phi
///   Fy =  dFt sin phi - dFr sin kappa cos phi + dFa cos kappa cos phi
///   Fz =                dFr cos kappa          + dFa sin kappa
/// (kappa = 90 deg gives design.md's Fx = -Ft cos phi - Fr sin phi,
/// Fy = Ft sin phi - Fr cos phi, Fz = Fa). The workpiece gets the opposite.
/// Torque about the tool axis: sum dFt R_j (N mm -> N m).
///
/// probe_mm: the edge point is looked up probe_mm outside the edge radius.
/// A height map marks a cell removed when its centre was within R of the
/// path, so a point just outside the circle can sit in a removed cell; one
/// cell (more than the half diagonal) makes the material ahead of the edge
/// read reliably. The engaged arc's ends move by about probe/R rad; where the
/// circle runs tangent to a cut boundary it can read up to acos(R/(R+probe))
/// of extra arc, where the chip is < that fraction of f.
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "process/cutting_coefficients.hpp"
#include "process/tool.hpp"

namespace twin::process {

struct ForceModelOptions {
  double dz_mm{0.1};             ///< axial disk height
  double angle_step_deg{1.5};    ///< largest spindle rotation between force samples within a tick
  double engagement_step_deg{1.0};  ///< angular sampling of the reported engaged arc
  /// Throws ConfigError naming `where` when dz is outside [0.005, 2] mm or a step outside [0.05, 10] deg.
  void validate(const std::string& where) const;
};

/// The dynamic (regenerative) chip of a vibrating tool: du_mm[m-1] = u(t) -
/// u(t - m T), the tool's deflection now against m tooth periods T ago. The
/// edge of flute j cuts the surface the nearest earlier flute left:
///   h_r = min_{m=1..N} ( m f . n + R_j(z) - R_{j-m}(z) + du_m . n ),  n = (sin phi_j, cos phi_j),
/// so a tooth that a vibration lifts out of the cut leaves the surface to the
/// next (Tlusty's multiple regeneration).
struct Regeneration {
  std::array<std::array<double, 2>, 16> du_mm{};   ///< m = 1 .. flutes (at most 16)
};

/// The result of one force evaluation at one spindle angle.
struct ForceSample {
  std::array<double, 3> F_tool_N{};   ///< force on the tool
  double torque_Nm{0.0};              ///< cutting torque about the tool axis (resists the spindle)
  double chip_max_mm{0.0};
  double z_engaged_max_mm{-1.0};      ///< highest cutting disk above the tip; < 0 when none cuts
  int cutting_elements{0};
};

class MillingForceModel {
 public:
  /// Throws ConfigError when tool, coefficients, options or |lead| >= 60 deg are invalid.
  MillingForceModel(const ToolGeometry& tool, const CuttingCoefficients& coefficients, double lead_deg,
                    const ForceModelOptions& options);

  const ToolGeometry& tool() const noexcept { return tool_; }
  const CuttingCoefficients& coefficients() const noexcept { return k_; }
  const ForceModelOptions& options() const noexcept { return options_; }

  /// Force at spindle angle phi_rad with the tool tip at p_mm, feed per tooth
  /// vector f_mm (xy), disks up to z_top_mm (absolute) only. `material(x, y, z)`
  /// says whether a point lies in remaining material; probe_mm as above.
  /// With `regen`, the chip is the dynamic one of Regeneration (p_mm stays the
  /// undeflected tool: the material test is the rigid tool's).
  template <class Material>
  ForceSample sample(double phi_rad, const std::array<double, 3>& p_mm, const std::array<double, 2>& f_mm,
                     double z_top_mm, double probe_mm, const Material& material,
                     const Regeneration* regen = nullptr) const;

  /// Engaged arc (deg) of the edge circle at height z_local_mm above the tip:
  /// the angles where the edge moves into material (v_dir . r > 0) and the
  /// probe point lies in material. A Material with a member
  /// count_in_material(cx, cy, r, sin, cos, n, z), the number of the n points
  /// (cx + r sin[i], cy + r cos[i]) in material at height z, is asked once
  /// per run of sample angles; otherwise point by point.
  template <class Material>
  double engaged_arc_deg(const std::array<double, 3>& p_mm, const std::array<double, 2>& v_dir, double z_local_mm,
                         double probe_mm, const Material& material) const;

  /// The engagement sample angles i (at (i + 1/2) 360/n deg) with
  /// v_dir . (sin, cos) > 0: up to two runs [begin, end) of indices (two when
  /// the half circle wraps past index 0). Only the few angles next to the two
  /// ends of the half circle are tested; the others cannot change sign.
  struct ArcRuns {
    std::array<std::size_t, 2> begin{};
    std::array<std::size_t, 2> end{};
    int count{0};
  };
  ArcRuns forward_arc(const std::array<double, 2>& v_dir) const;

  /// Height above the tip of the disk nearest to z_mm.
  double disk_height_nearest_mm(double z_mm) const;

  /// Edge length (mm) of one flute below depth_mm above the tip, as the force
  /// sum weighs it (the element at depth_mm cut there).
  double edge_length_mm(double depth_mm) const;
  /// Number of edge elements per flute.
  std::size_t element_count() const noexcept { return disks_.size(); }

 private:
  struct Disk {
    double z_mm;        ///< evaluation height (middle of the element)
    double z_lo_mm;     ///< the element spans [z_lo, z_hi] above the tip
    double z_hi_mm;
    double kappa_lo;    ///< and [kappa_lo, kappa_hi] (corner elements; 0 on the flank)
    double kappa_hi;
    bool corner;
    double radius_mm;
    double sin_kappa;
    double cos_kappa;
    double db_mm;
    double sin_lag;
    double cos_lag;
  };
  /// Fraction of element d's width below z_top_local_mm (above the tip): 1 when all of it.
  double fraction_below(const Disk& d, double z_top_local_mm) const;
  ToolGeometry tool_;
  CuttingCoefficients k_;
  ForceModelOptions options_;
  double cos_lead_{1.0};
  double sin_lead_{0.0};
  std::vector<Disk> disks_;
  std::vector<double> dR_mm_;        ///< runout: R_j(z) - R, per element i and flute j at [i N + j]
  std::vector<std::array<double, 2>> flute_dir_;   ///< (sin, cos) of j 2 pi/N
  std::vector<double> arc_sin_;   ///< sin and cos of the engagement sample angles
  std::vector<double> arc_cos_;
};

template <class Material>
ForceSample MillingForceModel::sample(double phi_rad, const std::array<double, 3>& p_mm,
                                      const std::array<double, 2>& f_mm, double z_top_mm, double probe_mm,
                                      const Material& material, const Regeneration* regen) const {
  ForceSample out;
  const int N = tool_.flutes;
  const double f_abs = std::hypot(f_mm[0], f_mm[1]);
  double Fx = 0.0, Fy = 0.0, Fz = 0.0, T_Nmm = 0.0;
  const double s0 = std::sin(phi_rad);
  const double c0 = std::cos(phi_rad);
  const double z_top_local = z_top_mm - p_mm[2];
  for (std::size_t i = 0; i < disks_.size(); ++i) {
    const Disk& d = disks_[i];
    if (d.z_lo_mm >= z_top_local) break;
    const double w = d.z_hi_mm > z_top_local ? fraction_below(d, z_top_local) : 1.0;
    if (!(w > 0.0)) break;
    const double db = w * d.db_mm;
    // A cut element is probed in the middle of its part below the top.
    const double z_abs = p_mm[2] + (w < 1.0 ? 0.5 * (d.z_lo_mm + z_top_local) : d.z_mm);
    const double* dR = &dR_mm_[i * static_cast<std::size_t>(N)];
    for (int j = 0; j < N; ++j) {
      // sin, cos of phi + j 2 pi/N - lag by angle addition (no trigonometric call per element).
      const auto& fl = flute_dir_[static_cast<std::size_t>(j)];
      const double sj = s0 * fl[1] + c0 * fl[0];
      const double cj = c0 * fl[1] - s0 * fl[0];
      const double s = sj * d.cos_lag - cj * d.sin_lag;
      const double c = cj * d.cos_lag + sj * d.sin_lag;
      const double h0 = f_mm[0] * s + f_mm[1] * c;
      double h_r = h0;
      if (regen != nullptr) {
        h_r = 1e300;
        for (int m = 1; m <= N; ++m) {
          const auto& du = regen->du_mm[static_cast<std::size_t>(m - 1)];
          h_r = std::min(h_r, m * h0 + dR[j] - dR[((j - m) % N + N) % N] + du[0] * s + du[1] * c);
        }
      } else if (tool_.runout_rho_mm > 0.0) {
        const double Rj = dR[j];
        h_r = 1e300;
        for (int m = 1; m <= N; ++m) h_r = std::min(h_r, m * h0 + Rj - dR[((j - m) % N + N) % N]);
      }
      const double h = h_r * cos_lead_ * d.sin_kappa - f_abs * sin_lead_ * d.cos_kappa;
      if (!(h > 0.0)) continue;
      const double rj = d.radius_mm + dR[j];
      if (!material(p_mm[0] + (rj + probe_mm) * s, p_mm[1] + (rj + probe_mm) * c, z_abs)) continue;
      const double dFt = (k_.Kt.at(h) * h + k_.Kte_N_per_mm) * db;
      const double dFr = (k_.Kr.at(h) * h + k_.Kre_N_per_mm) * db;
      const double dFa = (k_.Ka.at(h) * h + k_.Kae_N_per_mm) * db;
      Fx += -dFt * c - dFr * d.sin_kappa * s + dFa * d.cos_kappa * s;
      Fy += dFt * s - dFr * d.sin_kappa * c + dFa * d.cos_kappa * c;
      Fz += dFr * d.cos_kappa + dFa * d.sin_kappa;
      T_Nmm += dFt * rj;
      out.chip_max_mm = std::max(out.chip_max_mm, h);
      out.z_engaged_max_mm = std::max(out.z_engaged_max_mm, d.z_mm);
      ++out.cutting_elements;
    }
  }
  out.F_tool_N = {Fx, Fy, Fz};
  out.torque_Nm = T_Nmm * 1e-3;
  return out;
}

template <class Material>
double MillingForceModel::engaged_arc_deg(const std::array<double, 3>& p_mm, const std::array<double, 2>& v_dir,
                                          double z_local_mm, double probe_mm, const Material& material) const {
  const std::size_t n = arc_sin_.size();
  const double r = tool_.edge_radius_mm(z_local_mm) + probe_mm;
  const double z_abs = p_mm[2] + z_local_mm;
  const ArcRuns runs = forward_arc(v_dir);
  int hits = 0;
  for (int k = 0; k < runs.count; ++k) {
    const std::size_t b = runs.begin[static_cast<std::size_t>(k)];
    const std::size_t e = runs.end[static_cast<std::size_t>(k)];
    if constexpr (requires { material.count_in_material(0.0, 0.0, 0.0, &arc_sin_[0], &arc_cos_[0], n, 0.0); }) {
      hits += material.count_in_material(p_mm[0], p_mm[1], r, &arc_sin_[b], &arc_cos_[b], e - b, z_abs);
    } else {
      for (std::size_t i = b; i < e; ++i)
        if (material(p_mm[0] + r * arc_sin_[i], p_mm[1] + r * arc_cos_[i], z_abs)) ++hits;
    }
  }
  return hits * (360.0 / static_cast<double>(n));
}

}  // namespace twin::process
