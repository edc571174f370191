#pragma once
/// What the position loops follow: the interpolated part program, or the
/// `<a>_ref_mm` columns of a measured run (replay).
#include <cstdint>
#include <memory>
#include <vector>

#include "controller/interpolator.hpp"
#include "twin/core/axis.hpp"

namespace twin::sim {

class ReferenceSource {
 public:
  virtual ~ReferenceSource() = default;
  /// The reference at tick k >= 0; after the end it holds the last value.
  virtual controller::ReferenceSample sample(std::int64_t k) const = 0;
  /// Number of ticks the reference covers (the run length before settling).
  virtual std::int64_t num_ticks() const = 0;
};

/// The interpolated part program.
class ProgramReference final : public ReferenceSource {
 public:
  explicit ProgramReference(controller::Trajectory trajectory) : trajectory_(std::move(trajectory)) {}
  controller::ReferenceSample sample(std::int64_t k) const override { return trajectory_.sample(k); }
  std::int64_t num_ticks() const override { return trajectory_.num_ticks(); }
  const controller::Trajectory& trajectory() const noexcept { return trajectory_; }

 private:
  controller::Trajectory trajectory_;
};

/// Sampled references, one value per tick per axis (replay of a measured run).
class SampledReference final : public ReferenceSource {
 public:
  /// x_ref_mm[axis] is empty for an absent axis; all others have the same length.
  SampledReference(AxisArray<std::vector<double>> x_ref_mm, double Ts_s);
  controller::ReferenceSample sample(std::int64_t k) const override;
  std::int64_t num_ticks() const override { return n_; }

 private:
  AxisArray<std::vector<double>> x_ref_mm_;
  double Ts_s_;
  std::int64_t n_{0};
};

/// A reference set from outside tick by tick (the FMU's x_ref_mm inputs).
class ExternalReference final : public ReferenceSource {
 public:
  explicit ExternalReference(const AxisArray<double>& x0_mm) : x_mm_(x0_mm) {}
  void set(const AxisArray<double>& x_mm) noexcept { x_mm_ = x_mm; }
  controller::ReferenceSample sample(std::int64_t) const override;
  std::int64_t num_ticks() const override { return 0; }

 private:
  AxisArray<double> x_mm_;
};

}  // namespace twin::sim
