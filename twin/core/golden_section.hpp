#pragma once
/// Golden-section search for the minimum of a unimodal function on an
/// interval (Kiefer 1953; Press et al., Numerical Recipes, 3rd ed., 10.2).
/// Each step keeps one interior point and evaluates one new one, so n
/// iterations cost n + 2 evaluations and shrink the bracket to
/// g^n (hi - lo), g = (sqrt 5 - 1) / 2 = 0.618. A maximum is the minimum of
/// -f; a search in log x passes log bounds and a function of exp(x).

#include <cmath>

namespace twin {

/// The final bracket [lo, hi] and its two interior points with their values.
struct GoldenSection {
  double lo{0.0}, hi{0.0};
  double x1{0.0}, f1{0.0};  ///< the lower interior point, hi - g (hi - lo)
  double x2{0.0}, f2{0.0};  ///< the upper interior point, lo + g (hi - lo)
  double mid() const { return 0.5 * (lo + hi); }
};

template <class F>
GoldenSection golden_section_min(F&& f, double lo, double hi, int iterations) {
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  GoldenSection s{lo, hi, hi - g * (hi - lo), 0.0, lo + g * (hi - lo), 0.0};
  s.f1 = f(s.x1);
  s.f2 = f(s.x2);
  for (int i = 0; i < iterations; ++i) {
    if (s.f1 < s.f2) {
      s.hi = s.x2;
      s.x2 = s.x1;
      s.f2 = s.f1;
      s.x1 = s.hi - g * (s.hi - s.lo);
      s.f1 = f(s.x1);
    } else {
      s.lo = s.x1;
      s.x1 = s.x2;
      s.f1 = s.f2;
      s.x2 = s.lo + g * (s.hi - s.lo);
      s.f2 = f(s.x2);
    }
  }
  return s;
}

}  // namespace twin
