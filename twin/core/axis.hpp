#pragma once
#include <array>
#include <cstddef>
#include <optional>
#include <string_view>

namespace twin {

enum class Axis : std::size_t { kX = 0, kY = 1, kZ = 2 };
inline constexpr std::size_t kNumAxes = 3;
inline constexpr std::array<Axis, kNumAxes> kAllAxes{Axis::kX, Axis::kY, Axis::kZ};

template <class T>
using AxisArray = std::array<T, kNumAxes>;

constexpr std::size_t index(Axis a) { return static_cast<std::size_t>(a); }
constexpr std::string_view axis_name(Axis a) {
  constexpr std::array<std::string_view, kNumAxes> names{"x", "y", "z"};
  return names[index(a)];
}
constexpr std::string_view axis_name(std::size_t i) { return axis_name(static_cast<Axis>(i)); }
inline std::optional<Axis> parse_axis(std::string_view s) {
  if (s == "x" || s == "X") return Axis::kX;
  if (s == "y" || s == "Y") return Axis::kY;
  if (s == "z" || s == "Z") return Axis::kZ;
  return std::nullopt;
}

}  // namespace twin
