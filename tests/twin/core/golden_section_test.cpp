// The shared golden-section search against closed forms.
#include "twin/core/golden_section.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace twin {
namespace {

// Oracle: the minimum of (x - 2)^2 + 1 at x = 2, and the bracket's width,
// which shrinks by exactly g = (sqrt 5 - 1) / 2 per iteration: after n it
// is g^n (hi - lo) (to rounding, 1e-12 relative), and the minimum lies in
// it. Evaluations: n + 2.
TEST(GoldenSection, BracketsTheMinimumAndShrinksByTheGoldenRatio) {
  int calls = 0;
  auto f = [&](double x) {
    ++calls;
    return (x - 2.0) * (x - 2.0) + 1.0;
  };
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  for (const int n : {0, 5, 20, 40}) {
    calls = 0;
    const GoldenSection s = golden_section_min(f, -3.0, 9.0, n);
    EXPECT_EQ(calls, n + 2);
    EXPECT_NEAR(s.hi - s.lo, std::pow(g, n) * 12.0, 1e-12 * 12.0) << n;
    EXPECT_LE(s.lo, 2.0) << n;
    EXPECT_GE(s.hi, 2.0) << n;
    EXPECT_DOUBLE_EQ(s.f1, f(s.x1));
    EXPECT_DOUBLE_EQ(s.f2, f(s.x2));
    EXPECT_LT(s.lo, s.x1);
    EXPECT_LT(s.x1, s.x2);
    EXPECT_LT(s.x2, s.hi);
  }
  EXPECT_NEAR(golden_section_min(f, -3.0, 9.0, 60).mid(), 2.0, 1e-7);
}

// Oracle: a maximum as the minimum of -f, searched in log x: the peak of
// x exp(-x / 3) is at x = 3 (d/dx = 0), and the search over log x in
// [log 0.1, log 100] finds it to 1e-6 relative after 60 iterations
// (0.618^60 x 6.9 = 2e-12 in log x; the peak's flatness leaves sqrt of the
// double's rounding, 1e-8, in x).
TEST(GoldenSection, AMaximumInLogX) {
  auto peak = [](double x) { return x * std::exp(-x / 3.0); };
  const GoldenSection s =
      golden_section_min([&](double lx) { return -peak(std::exp(lx)); }, std::log(0.1), std::log(100.0), 60);
  EXPECT_NEAR(std::exp(s.mid()), 3.0, 3e-6);
}

}  // namespace
}  // namespace twin
