#include "twin/structure/cut_study.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <tuple>

#include <fmt/format.h>

#include "process/workpiece.hpp"
#include "twin/core/error.hpp"

namespace twin::structure {
namespace {

constexpr double kPi = std::numbers::pi;
using P3 = std::array<double, 3>;

struct Probe {
  bool cuts{false};
  double phi_st{0.0}, phi_ex{0.0}, ap{0.0};
};

/// The engaged arc ahead of the tool at tip p moving along unit (ux, uy).
Probe probe(const process::HeightMapStock& stock, const process::ToolGeometry& tool, const P3& p, double ux,
            double uy, double step_rad) {
  const double R = tool.radius_mm() + stock.cell_mm();
  // y_f: x_f turned +90 deg.
  const double vx = -uy, vy = ux;
  Probe out;
  double top = p[2];
  const int n = static_cast<int>(std::ceil(kPi / step_rad));
  for (int i = 0; i <= n; ++i) {
    const double phi = kPi * i / n;
    const double x = p[0] + R * (std::sin(phi) * ux + std::cos(phi) * vx);
    const double y = p[1] + R * (std::sin(phi) * uy + std::cos(phi) * vy);
    top = std::max(top, std::min(stock.top_z_at_mm(x, y), p[2] + tool.flute_length_mm));
  }
  out.ap = top - p[2];
  if (out.ap <= 1e-6) return out;
  const double z_mid = p[2] + 0.5 * out.ap;
  bool first = true;
  for (int i = 0; i <= n; ++i) {
    const double phi = kPi * i / n;
    const double x = p[0] + R * (std::sin(phi) * ux + std::cos(phi) * vx);
    const double y = p[1] + R * (std::sin(phi) * uy + std::cos(phi) * vy);
    if (!stock.has_material(x, y, z_mid)) continue;
    if (first) out.phi_st = phi, first = false;
    out.phi_ex = phi;
  }
  out.cuts = !first && out.phi_ex > out.phi_st;
  return out;
}

}  // namespace

std::vector<CutCondition> study_cuts(const controller::Program& program, const process::ProcessSetup& setup,
                                     const CutStudyOptions& options) {
  setup.tool.validate("cut study: tool");
  setup.stock.validate("cut study: stock");
  if (!(options.step_mm > 0.0) || !(options.angle_step_deg > 0.0))
    throw ConfigError("cut study: step and angle step must be > 0");
  process::HeightMapStock stock(setup.stock);
  const double step_rad = options.angle_step_deg * kPi / 180.0;
  const int N = setup.tool.flutes;
  using Key = std::tuple<long, long, long, long, long, long>;
  std::map<Key, CutCondition> groups;
  for (const controller::Block& b : program.blocks) {
    if (b.kind == controller::MotionKind::kDwell) continue;
    const bool arc = b.kind == controller::MotionKind::kArcCw || b.kind == controller::MotionKind::kArcCcw;
    const P3 s{b.start_mm[0], b.start_mm[1], b.start_mm[2]};
    const P3 e{b.end_mm[0], b.end_mm[1], b.end_mm[2]};
    // Position and tangent at parameter t in [0, 1].
    double a0 = 0.0, sweep = 0.0, r = 0.0;
    const double cx = b.center_mm[0], cy = b.center_mm[1];
    if (arc) {
      a0 = std::atan2(s[1] - cy, s[0] - cx);
      double a1 = std::atan2(e[1] - cy, e[0] - cx);
      r = std::hypot(s[0] - cx, s[1] - cy);
      sweep = a1 - a0;
      if (b.kind == controller::MotionKind::kArcCcw) {
        if (sweep <= 1e-12) sweep += 2 * kPi;
      } else if (sweep >= -1e-12) {
        sweep -= 2 * kPi;
      }
    }
    auto at = [&](double t) {
      if (!arc) return P3{s[0] + t * (e[0] - s[0]), s[1] + t * (e[1] - s[1]), s[2] + t * (e[2] - s[2])};
      const double a = a0 + t * sweep;
      return P3{cx + r * std::cos(a), cy + r * std::sin(a), s[2] + t * (e[2] - s[2])};
    };
    const double len_xy = arc ? std::abs(sweep) * r : std::hypot(e[0] - s[0], e[1] - s[1]);
    const double len = std::hypot(len_xy, e[2] - s[2]);
    if (len <= 1e-9) continue;
    const int n = std::max(1, static_cast<int>(std::ceil(len / options.step_mm)));
    P3 prev = s;
    for (int i = 1; i <= n; ++i) {
      const double t = static_cast<double>(i) / n;
      const P3 p = at(t);
      const double dx = p[0] - prev[0], dy = p[1] - prev[1];
      const double dxy = std::hypot(dx, dy);
      // Only feed moves in the plane are studied for chatter; every move cuts the stock.
      if (b.kind != controller::MotionKind::kRapid && dxy > 1e-9 && b.spindle_rpm != 0.0) {
        const Probe pr = probe(stock, setup.tool, prev, dx / dxy, dy / dxy, step_rad);
        if (pr.cuts) {
          CutCondition c;
          c.immersion = {pr.phi_st, pr.phi_ex};
          c.ap_mm = pr.ap;
          c.feed_angle_deg = std::atan2(dy, dx) * 180.0 / kPi;
          c.spindle_rpm = b.spindle_rpm;
          c.fz_mm = b.feed_mm_per_min / (N * std::abs(b.spindle_rpm));
          const Key key{std::lround(pr.phi_st * 90.0 / kPi), std::lround(pr.phi_ex * 90.0 / kPi),
                        std::lround(pr.ap * 20.0), std::lround(c.spindle_rpm), std::lround(c.fz_mm * 1e4),
                        std::lround(c.feed_angle_deg / 2.0)};
          auto [it, fresh] = groups.try_emplace(key, c);
          if (fresh) it->second.first_line = b.line;
          it->second.length_mm += std::hypot(dxy, p[2] - prev[2]);
        }
      }
      stock.remove_sweep(setup.tool, prev, p, true);
      prev = p;
    }
  }
  std::vector<CutCondition> out;
  for (auto& [k, c] : groups) out.push_back(c);
  std::stable_sort(out.begin(), out.end(),
                   [](const CutCondition& a, const CutCondition& b) { return a.length_mm > b.length_mm; });
  return out;
}

LinearisedCoefficients linearise_coefficients(const process::CuttingCoefficients& k, const CutCondition& cut) {
  const double st = cut.immersion.phi_st_rad, ex = cut.immersion.phi_ex_rad;
  if (!(ex > st)) throw ConfigError("lobes: the cut has no immersion");
  LinearisedCoefficients out;
  out.h_mean_mm = cut.fz_mm * (std::cos(st) - std::cos(ex)) / (ex - st);
  // d(K(h) h)/dh with K = a + b exp(-c h): a + b exp(-c h) (1 - c h).
  auto dyn = [h = out.h_mean_mm](const process::ExpCoefficient& q) {
    return q.a_N_per_mm2 + q.b_N_per_mm2 * std::exp(-q.c_per_mm * h) * (1.0 - q.c_per_mm * h);
  };
  out.Ktc_N_per_mm2 = dyn(k.Kt);
  if (!(out.Ktc_N_per_mm2 > 0.0))
    throw ConfigError(fmt::format("lobes: the dynamic tangential coefficient at h = {:.4g} mm is not positive",
                                  out.h_mean_mm));
  out.Kr_ratio = std::max(0.0, dyn(k.Kr)) / out.Ktc_N_per_mm2;
  return out;
}

}  // namespace twin::structure
