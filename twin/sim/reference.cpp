#include "twin/sim/reference.hpp"

#include <algorithm>
#include <cmath>

#include "twin/core/check.hpp"

namespace twin::sim {

SampledReference::SampledReference(AxisArray<std::vector<double>> x_ref_mm, double Ts_s)
    : x_ref_mm_(std::move(x_ref_mm)), Ts_s_(Ts_s) {
  for (const auto& v : x_ref_mm_) {
    if (v.empty()) continue;
    TWIN_DEMAND(n_ == 0 || static_cast<std::int64_t>(v.size()) == n_);
    n_ = static_cast<std::int64_t>(v.size());
  }
  TWIN_DEMAND(n_ > 0);
}

controller::ReferenceSample SampledReference::sample(std::int64_t k) const {
  controller::ReferenceSample s;
  const std::int64_t i = std::clamp<std::int64_t>(k, 0, n_ - 1);
  const std::int64_t ip = std::max<std::int64_t>(i - 1, 0);
  double v2 = 0.0;
  for (std::size_t a = 0; a < kNumAxes; ++a) {
    if (x_ref_mm_[a].empty()) continue;
    s.x_mm[a] = x_ref_mm_[a][static_cast<std::size_t>(i)];
    s.v_mm_per_s[a] = (k >= n_ || k <= 0) ? 0.0 : (s.x_mm[a] - x_ref_mm_[a][static_cast<std::size_t>(ip)]) / Ts_s_;
    v2 += s.v_mm_per_s[a] * s.v_mm_per_s[a];
  }
  s.path_speed_mm_per_s = std::sqrt(v2);
  s.block = -1;
  s.done = k >= n_ - 1;
  return s;
}

controller::ReferenceSample ExternalReference::sample(std::int64_t) const {
  controller::ReferenceSample s;
  s.x_mm = x_mm_;
  return s;
}

}  // namespace twin::sim
