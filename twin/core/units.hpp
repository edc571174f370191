#pragma once
/// Named conversion constants. Convert only through these.
#include <numbers>

namespace twin {
inline constexpr double kPi = std::numbers::pi;
inline constexpr double kMPerMm = 1e-3;         // m per mm
inline constexpr double kMmPerM = 1e3;
inline constexpr double kSPerMin = 60.0;        // s per min
inline constexpr double kRadPerDeg = kPi / 180.0;
inline constexpr double kDegPerRad = 180.0 / kPi;
inline constexpr double kRadPerRev = 2.0 * kPi;
/// rad/s per rpm.
inline constexpr double kRadPerSPerRpm = kRadPerRev / kSPerMin;
inline constexpr double kMmPerInch = 25.4;
}  // namespace twin
