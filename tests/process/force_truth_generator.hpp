#pragma once
// An independent generator of dynamometer force series for the truth tests
// of `twin calibrate` on forces. It shares no code with the twin's force
// model or with twin/force_calibrate: a direct per-slice sum of the
// textbook mechanistic model (Altintas, Manufacturing Automation, ch. 2),
// one slice of dz per height, every sample evaluated at its exact spindle
// angle, with the one effect the series carries:
//   runout      R_j(z) = R + rho cos(lambda - j 2pi/N + z tan(beta)/R),
//               h_j = min_m (m c sin phi_j + R_j - R_{j-m})     (Kline-DeVor)
//   size effect K_q(h) = a_q + b_q exp(-c h)                       (Duan 2025 eq. 1)
//   wear        every coefficient times (1 + w L), L the cut length so far
//   sensor mode x'' + 2 zeta wn x' + wn^2 x = wn^2 F per axis, integrated by
//               RK4 at 20 times the log rate with the force held per step
// plus what every dynamometer log holds: a zero offset and drift per axis,
// white noise, values rounded to 0.01 N, air before the cut.
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace twin::process::truth {

struct TruthSeries {
  double D_mm{10.0};
  int N{2};
  double helix_deg{30.0};
  double ap_mm{2.0};
  double rpm{6000.0};
  std::vector<double> fz_mm{0.03, 0.06, 0.09, 0.12};
  std::array<double, 3> Kc{800.0, 260.0, 100.0};   // a_q, N/mm^2
  std::array<double, 3> Kb{0.0, 0.0, 0.0};         // b_q, N/mm^2
  double c_per_mm{0.0};
  std::array<double, 3> Ke{20.0, 26.0, 3.0};       // N/mm
  double rho_mm{0.0};
  double lambda_deg{0.0};
  double mode_f_hz{0.0};
  double mode_zeta{0.0};
  double wear_per_mm{0.0};
  double fs_hz{10000.0};
  double air_s{0.05};
  double duration_s{0.45};
  double noise_N{1.5};
  bool log_angle{true};
  unsigned seed{7};
};

// Force on the workpiece at flute-0 angle phi (slot, feed +x), no wear.
inline std::array<double, 3> truth_force(const TruthSeries& s, double fz, double phi) {
  constexpr double pi = std::numbers::pi;
  const double R = 0.5 * s.D_mm;
  const double tb = std::tan(s.helix_deg * pi / 180.0);
  const int nz = 60;
  const double dz = s.ap_mm / nz;
  std::array<double, 3> F{0.0, 0.0, 0.0};
  for (int i = 0; i < nz; ++i) {
    const double z = (i + 0.5) * dz;
    for (int j = 0; j < s.N; ++j) {
      double pj = std::fmod(phi + j * 2 * pi / s.N - z * tb / R, 2 * pi);
      if (pj < 0) pj += 2 * pi;
      if (pj > pi) continue;   // slot: engaged from 0 to 180 deg
      double h = fz * std::sin(pj);
      if (s.rho_mm > 0.0) {
        auto radius = [&](int jj) { return R + s.rho_mm * std::cos(s.lambda_deg * pi / 180.0 - jj * 2 * pi / s.N + z * tb / R); };
        h = 1e9;
        for (int m = 1; m <= s.N; ++m) h = std::min(h, m * fz * std::sin(pj) + radius(j) - radius(j - m));
      }
      if (h <= 0.0) continue;
      double dF[3];
      for (int q = 0; q < 3; ++q) dF[q] = ((s.Kc[q] + s.Kb[q] * std::exp(-s.c_per_mm * h)) * h + s.Ke[q]) * dz;
      // On the tool: Fx = -Ft cos - Fr sin, Fy = Ft sin - Fr cos, Fz = Fa; the workpiece gets the opposite.
      F[0] -= -dF[0] * std::cos(pj) - dF[1] * std::sin(pj);
      F[1] -= dF[0] * std::sin(pj) - dF[1] * std::cos(pj);
      F[2] -= dF[2];
    }
  }
  return F;
}

// Writes <dir>/fzX.XXX/{trace.csv, meta.json}, one run per feed, cut in that order.
inline void write_truth_series(const std::filesystem::path& dir, const TruthSeries& s) {
  constexpr double pi = std::numbers::pi;
  std::filesystem::create_directories(dir);
  std::mt19937 rng(s.seed);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  std::normal_distribution<double> noise(0.0, s.noise_N);
  double L_mm = 0.0;
  for (std::size_t r = 0; r < s.fz_mm.size(); ++r) {
    const double fz = s.fz_mm[r];
    const double feed_mm_min = fz * s.N * s.rpm;
    char name[32];
    std::snprintf(name, sizeof name, "fz%.3f", fz);
    const auto run = dir / name;
    std::filesystem::create_directories(run);
    const double phi0 = (U(rng) + 1.0) * pi;
    std::array<double, 3> off{}, drift{};
    for (int a = 0; a < 3; ++a) {
      off[a] = 5.0 * U(rng);
      drift[a] = 2.0 * U(rng);
    }
    const int sub = s.mode_f_hz > 0.0 ? 20 : 1;
    const double dt = 1.0 / (s.fs_hz * sub);
    const double wn = 2 * pi * s.mode_f_hz;
    std::array<double, 3> x{}, v{};
    const double omega = 2 * pi * s.rpm / 60.0;
    const double v_mm_s = feed_mm_min / 60.0;
    std::ofstream csv(run / "trace.csv");
    csv << "t_s,fx_N,fy_N,fz_N,spindle_rpm" << (s.log_angle ? ",spindle_deg" : "") << "\n";
    const long rows = std::lround(s.duration_s * s.fs_hz);
    std::array<double, 3> F{};
    for (long k = 0; k < rows; ++k) {
      const double t = k / s.fs_hz;
      if (sub == 1) {
        F = {0.0, 0.0, 0.0};
        if (t >= s.air_s) {
          F = truth_force(s, fz, phi0 + omega * t);
          const double scale = 1.0 + s.wear_per_mm * (L_mm + v_mm_s * (t - s.air_s));
          for (double& f : F) f *= scale;
        }
      }
      char line[200];
      double out[3];
      for (int a = 0; a < 3; ++a)
        out[a] = std::round(((sub > 1 ? x[a] : F[a]) + off[a] + drift[a] * t + noise(rng)) * 100.0) / 100.0;
      double deg = std::fmod((phi0 + omega * t) * 180.0 / pi, 360.0);
      if (deg < 0) deg += 360.0;
      if (s.log_angle)
        std::snprintf(line, sizeof line, "%.6f,%.2f,%.2f,%.2f,%.0f,%.3f\n", t, out[0], out[1], out[2], s.rpm, deg);
      else
        std::snprintf(line, sizeof line, "%.6f,%.2f,%.2f,%.2f,%.0f\n", t, out[0], out[1], out[2], s.rpm);
      csv << line;
      // The sensor mode: integrate over [t_k, t_k+1) (the log holds its state at t_k).
      for (int q = 0; q < sub && sub > 1; ++q) {
        const double tq = (k * sub + q) * dt;
        F = {0.0, 0.0, 0.0};
        if (tq >= s.air_s) {
          F = truth_force(s, fz, phi0 + omega * tq);
          const double scale = 1.0 + s.wear_per_mm * (L_mm + v_mm_s * (tq - s.air_s));
          for (double& f : F) f *= scale;
        }
        {
          for (int a = 0; a < 3; ++a) {
            auto acc = [&](double xx, double vv) { return wn * wn * (F[a] - xx) - 2 * s.mode_zeta * wn * vv; };
            const double k1x = v[a], k1v = acc(x[a], v[a]);
            const double k2x = v[a] + 0.5 * dt * k1v, k2v = acc(x[a] + 0.5 * dt * k1x, v[a] + 0.5 * dt * k1v);
            const double k3x = v[a] + 0.5 * dt * k2v, k3v = acc(x[a] + 0.5 * dt * k2x, v[a] + 0.5 * dt * k2v);
            const double k4x = v[a] + dt * k3v, k4v = acc(x[a] + dt * k3x, v[a] + dt * k3v);
            x[a] += dt / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
            v[a] += dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
          }
        }
      }
    }
    L_mm += v_mm_s * (s.duration_s - s.air_s);
    std::ofstream meta(run / "meta.json");
    meta << "{\"machine\": null, \"axes\": [], \"sample_period_s\": " << 1.0 / s.fs_hz
         << ", \"cut\": {\"tool\": {\"diameter_mm\": " << s.D_mm << ", \"flutes\": " << s.N
         << ", \"helix_deg\": " << s.helix_deg << ", \"corner_radius_mm\": 0}, \"spindle_rpm\": " << s.rpm
         << ", \"feed_mm_per_min\": " << feed_mm_min << ", \"feed_direction_deg\": 0, \"ae_mm\": " << s.D_mm
         << ", \"ap_mm\": " << s.ap_mm << ", \"milling\": \"slot\", \"material\": \"truth\"}}\n";
  }
}

}  // namespace twin::process::truth
