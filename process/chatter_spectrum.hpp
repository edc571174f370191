#pragma once
/// Chatter from the force's spectrum: the largest line at a non-harmonic of
/// the tooth frequency near the tool's modes against the tooth harmonics.
///
/// Over samples [b, e) of the x and y force (Ts apart), Hann-windowed, window
/// length L = (e - b) Ts:
///   r = sqrt( max over f in [f_lo, f_hi], on the 1/L grid, more than 3/L from
///             any k f_tooth, of P(f)  /  max over k >= 0 of P(k f_tooth) ),
///   P(f) = |X_x(f)|^2 + |X_y(f)|^2
/// (k = 0, the mean force, counts as a harmonic: in a slot with an even number
/// of teeth the tooth harmonics of x and y nearly cancel). A stable cut rings
/// down after a disturbance (r falls to a floor of about 1e-3: the height
/// map's cells modulate the engagement at v / cell); chatter grows until teeth
/// leave the cut and holds a limit cycle with r of order 0.1 to 1.
#include <array>
#include <cstddef>
#include <vector>

namespace twin::process {

struct ChatterSpectrum {
  double ratio{0.0};
  double chatter_Hz{0.0};   ///< the largest non-harmonic line
};

ChatterSpectrum chatter_spectrum(const std::vector<std::array<double, 2>>& F_N, std::size_t b, std::size_t e,
                                 double Ts_s, double tooth_Hz, double f_lo_Hz, double f_hi_Hz);

/// The verdict from two consecutive windows: chatter when r_late >= 0.05 (a
/// limit cycle), or when it grew by 20 % above the floor (r_late > 2e-3).
inline bool chatter_verdict(double r_early, double r_late) {
  return r_late >= 0.05 || (r_late > 2e-3 && r_late >= 1.2 * r_early);
}

}  // namespace twin::process
