#pragma once
/// Quantisation of the fed-back position: an encoder of resolution r reports
/// round(x / r) * r. A resolution of 0 means an ideal (unquantised) sensor.
#include <cmath>

namespace twin::controller {

struct Encoder {
  double resolution_mm{0.001};
  double measure_mm(double x_mm) const noexcept {
    if (!(resolution_mm > 0.0)) return x_mm;
    return std::nearbyint(x_mm / resolution_mm) * resolution_mm;
  }
};

}  // namespace twin::controller
