#pragma once
/// Stability lobes of regenerative milling chatter: the zero-order (average
/// tooth-passing) solution of Altintas and Budak (CIRP Annals 44/1, 1995;
/// Altintas, Manufacturing Automation, 2nd ed., ch. 4.4).
///
/// The tool tip is flexible in the machine's x and y, each direction a sum of
/// uncoupled modes (modal stiffness k, natural frequency fn, damping ratio zeta):
///   G(w) = sum_r 1 / (k_r (1 - (w/w_r)^2 + 2 i zeta_r w/w_r))      [mm/N]
/// Immersion angles phi are measured clockwise from +y_f, the feed along +x_f
/// (the convention of process/milling_force.hpp). The dynamic chip of a tooth
/// is the difference of the present and the previous tooth's vibration along
/// its radial direction; averaged over the tooth period, with Kr = Krc/Ktc,
///   F = (1/2) a Ktc [A0] Delta,   [A0] = N/(2 pi) [alpha],
///   alpha_xx = 1/2 [ cos 2phi - 2 Kr phi + Kr sin 2phi ] from phi_st to phi_ex
///   alpha_xy = 1/2 [-sin 2phi - 2 phi    + Kr cos 2phi ]
///   alpha_yx = 1/2 [-sin 2phi + 2 phi    + Kr cos 2phi ]
///   alpha_yy = 1/2 [-cos 2phi - 2 Kr phi - Kr sin 2phi ]
/// At a chatter frequency wc the loop has a non-trivial solution when
///   det(I + Lambda [alpha][G(i wc)]) = 0,  Lambda = -N/(4 pi) a Ktc (1 - exp(-i wc T)),
/// so Lambda = -1/lambda for each eigenvalue lambda of [alpha][G] (G in the feed
/// frame). With kappa = Lambda_I / Lambda_R:
///   a_lim = -2 pi Lambda_R (1 + kappa^2) / (N Ktc)
///   psi = atan(kappa), eps = pi - 2 psi, T = (eps + 2 k pi) / wc, n = 60 / (N T)
/// for lobe k = 0, 1, ... Only Lambda_R < 0 gives a positive depth.
#include <complex>
#include <string>
#include <vector>

namespace twin::process {

/// One mode of the tool tip in one direction.
struct ToolTipMode {
  double fn_Hz{0.0};
  double zeta{0.0};              ///< damping ratio, (0, 1)
  double k_N_per_m{0.0};         ///< modal stiffness
  /// Throws ConfigError naming `where` for a non-finite or non-physical value.
  void validate(const std::string& where) const;
};

/// The tool-tip frequency response in the machine's x and y (uncoupled modes).
struct ToolTipFrf {
  std::vector<ToolTipMode> x;
  std::vector<ToolTipMode> y;
  void validate(const std::string& where) const;
  bool empty() const noexcept { return x.empty() && y.empty(); }
  /// Direct FRF of one direction at w_rad_per_s (mm/N).
  static std::complex<double> direct_mm_per_N(const std::vector<ToolTipMode>& modes, double w_rad_per_s);
  /// Lowest and highest natural frequencies of all modes (Hz).
  double fn_min_Hz() const;
  double fn_max_Hz() const;
};

enum class MillingMode { kUp, kDown };

/// Entry and exit immersion (rad) of a cut of radial depth ae_mm with a tool of
/// diameter D_mm: up milling starts at 0, down milling ends at pi, a slot (ae = D)
/// runs from 0 to pi. Throws ConfigError for ae outside (0, D].
struct Immersion {
  double phi_st_rad{0.0};
  double phi_ex_rad{0.0};
  static Immersion of_cut(double ae_mm, double D_mm, MillingMode mode, const std::string& where);
};

/// The averaged directional coefficients [alpha] (dimensionless) of the cut.
struct DirectionalCoefficients {
  double xx{0.0}, xy{0.0}, yx{0.0}, yy{0.0};
  static DirectionalCoefficients of(const Immersion& im, double Kr_ratio);
};

struct LobeSettings {
  int teeth{2};
  double Ktc_N_per_mm2{0.0};        ///< tangential cutting coefficient (linearised at the cut's chip)
  double Kr_ratio{0.0};             ///< Krc / Ktc
  Immersion immersion{};
  double feed_angle_deg{0.0};       ///< feed direction in the machine's xy (0 = +x)
  int lobes{8};                     ///< lobe numbers 0 .. lobes-1
  int frequencies{1500};            ///< chatter frequencies scanned per eigenvalue branch
  void validate(const std::string& where) const;
};

/// One point of one lobe: at chatter frequency chatter_Hz the cut is critically
/// stable at depth a_lim_mm when the spindle turns at spindle_rpm.
struct LobePoint {
  double spindle_rpm{0.0};
  double a_lim_mm{0.0};
  double chatter_Hz{0.0};
};

/// One lobe curve (one lobe number, one eigenvalue branch), ordered by chatter frequency.
struct Lobe {
  int number{0};
  int branch{0};
  std::vector<LobePoint> points;
};

struct StabilityLobes {
  std::vector<Lobe> lobes;
  double a_lim_min_mm{0.0};          ///< the smallest critical depth of any speed
  double a_lim_min_chatter_Hz{0.0};
  /// The stability boundary at a spindle speed: the smallest critical depth of
  /// all lobes covering it (linear in the chatter frequency between scanned
  /// points). +inf when no lobe covers the speed.
  double critical_depth_mm(double spindle_rpm) const;
  /// The lobe point that sets critical_depth_mm (its chatter frequency); nullptr-free:
  /// returns a point with a_lim_mm = +inf when none covers the speed.
  LobePoint boundary_at(double spindle_rpm) const;
};

/// The zero-order lobes of a tool tip and a cut. Throws ConfigError for invalid inputs.
StabilityLobes zero_order_lobes(const ToolTipFrf& frf, const LobeSettings& settings);

}  // namespace twin::process
