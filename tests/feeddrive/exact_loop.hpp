#pragma once
// The oracle of the drive bank's linear response, shared by its test and its
// benchmark: with friction off, a drive between ticks is the linear plant
//   d/dt [x_mm, w] = [[0, rg], [0, -B/J]] [x_mm, w] + [0, Ka Kt / J] u,
// so under the FADAL PID (u held over each tick) its exact step is the
// zero-order-hold matrix exponential expm([[A, b], [0, 0]] Ts).
#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>
#include <algorithm>
#include <cmath>
#include <vector>

#include "fadal_fixture.hpp"
#include "feeddrive/drive_bank.hpp"

namespace twin::feeddrive::testing {

/// Exact ZOH step of one frictionless axis over kTs_s.
struct ExactAxis {
  Eigen::Matrix2d Ad;
  Eigen::Vector2d Bd;
  explicit ExactAxis(const DriveParams& p) {
    Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
    M(0, 1) = p.rg_mm_per_rad;
    M(1, 1) = -p.B_kg_m2_per_s / p.J_kg_m2;
    M(1, 2) = p.Ka_A_per_V * p.Kt_Nm_per_A / p.J_kg_m2;
    const Eigen::Matrix3d E = (M * kTs_s).exp();
    Ad = E.topLeftCorner<2, 2>();
    Bd = E.topRightCorner<2, 1>();
  }
};

/// Runs `bank` (axes `params`, friction off, at rest at x0_mm) and the exact
/// ZOH solution of each axis for `ticks` ticks, each under its own HandPid of
/// `gains` (no quantisation) following ref_mm(axis, k); returns the largest
/// |x_bank - x_exact| over the axes and ticks.
template <class Ref>
double max_deviation_from_exact(DriveBank& bank, const std::vector<DriveParams>& params,
                                const std::vector<PidGains>& gains, const Ref& ref_mm, long ticks, double x0_mm) {
  const std::size_t n = params.size();
  std::vector<HandPid> pid_bank;
  std::vector<ExactAxis> exact;
  for (std::size_t a = 0; a < n; ++a) {
    pid_bank.emplace_back(gains[a], kTs_s);
    exact.emplace_back(params[a]);
  }
  std::vector<HandPid> pid_exact = pid_bank;
  std::vector<Eigen::Vector2d> z(n, Eigen::Vector2d(x0_mm, 0.0));
  std::vector<DriveInput> in(n);
  double worst = 0.0;
  for (long k = 0; k < ticks; ++k) {
    for (std::size_t a = 0; a < n; ++a) {
      const double r = ref_mm(static_cast<int>(a), k);
      in[a].u_V = pid_bank[a].step(r, bank.output(a).x_meas_mm);
      const double u_exact = pid_exact[a].step(r, z[a](0));
      z[a] = exact[a].Ad * z[a] + exact[a].Bd * u_exact;
    }
    bank.advance(k * kTs_s, (k + 1) * kTs_s, in);
    for (std::size_t a = 0; a < n; ++a) worst = std::max(worst, std::abs(bank.output(a).x_mm - z[a](0)));
  }
  return worst;
}

}  // namespace twin::feeddrive::testing
