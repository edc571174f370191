// MillingProcess::step, tick by tick through a cut into and out of an inner
// corner, against a straightforward evaluation of the same equations
// (docs/process.md) written here and sharing no code with process/ beyond
// the parameter structs: per element and flute its own sin and cos of the
// immersion, K(h) = a + b exp(-c h) (Duan 2025 eq. 1) at every chip, the
// chip of Duan eq. 4 with lead, every engagement sample angle tested, and a
// height map whose every update visits every cell within reach of the swept
// segment (the process visits only the cells a move can still lower, skips
// blocks of cells below its reach, and works several cells at a time).
//
// What may differ: rounding. The process turns its angles by angle addition
// and computes the same distances in another order, so forces differ by a
// few ulps of the element sums (below 1e-13 of the peak here). Which elements
// cut (the chip sign and the probe's material test) decides the force in
// steps of one element's K h db, from hundredths of a newton where the chip
// starts to several newtons, so a tolerance of 1e-9 of the peak force (about
// 2e-7 N) accepts rounding and nothing else: a single element decided
// differently in a single tick fails the test. The engaged arc is a
// count of sample angles and must be equal. Every cell's top must be equal at
// the end (the stored float of the same cut height). The removed volumes may
// differ by what each visit of a cell adds when its float top lies above the
// double height it is cut to by less than half a float ulp (3e-8 mm): the
// plain sweep visits many more cells, so 1e-6 of the volume.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <vector>

#include "process/milling_process.hpp"
#include "twin/io/process_yaml.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::process {
namespace {

constexpr double kPiRef = std::numbers::pi;

/// The documented model, evaluated the plain way.
class ReferenceProcess {
 public:
  explicit ReferenceProcess(const ProcessSetup& s)
      : tool_(s.tool), k_(s.coefficients), opt_(s.options), stock_(s.stock),
        phi_(s.spindle_angle0_deg * kPiRef / 180.0), lead_(s.lead_deg * kPiRef / 180.0) {
    build_elements();
    build_stock();
  }

  void remove_swept(std::array<double, 3> p0, std::array<double, 3> p1) {
    sweep(p0, p1);
    swept_once_ = true;
    last_ = p1;
  }

  ProcessOutput step(const ProcessInput& in) {
    ProcessOutput out;
    const auto& p = in.p_mm;
    const auto& v = in.v_mm_per_s;
    const double omega = in.spindle_rpm * 2.0 * kPiRef / 60.0;
    const double speed = std::hypot(v[0], v[1]);
    if (in.spindle_rpm > 0.0 && p[2] < stock_.top_z_mm) {
      const double n_rev_per_s = in.spindle_rpm / 60.0;
      const std::array<double, 2> f{v[0] / (tool_.flutes * n_rev_per_s), v[1] / (tool_.flutes * n_rev_per_s)};
      const int n_sub =
          std::max(1, static_cast<int>(std::ceil(omega * in.Ts_s / (opt_.angle_step_deg * kPiRef / 180.0) - 1e-9)));
      const double dt = in.Ts_s / n_sub;
      double T_sum = 0.0;
      for (int s = 0; s < n_sub; ++s) {
        const std::array<double, 3> ps{p[0] + v[0] * s * dt, p[1] + v[1] * s * dt, p[2] + v[2] * s * dt};
        const Sample fs = force(phi_ + omega * s * dt, ps, f);
        for (int a = 0; a < 3; ++a) {
          out.F_avg_N[a] -= fs.F[a] / n_sub;
          if (s == 0) out.F_N[a] = -fs.F[a];
        }
        T_sum += fs.T_Nm;
        out.chip_mm = std::max(out.chip_mm, fs.chip);
      }
      out.spindle_torque_Nm = T_sum / n_sub;
      out.power_W = out.spindle_torque_Nm * omega;
      if (speed > 0.0) out.engagement_deg = engagement(p, {v[0] / speed, v[1] / speed});
    }
    phi_ = std::fmod(phi_ + omega * in.Ts_s, 2.0 * kPiRef);
    const std::array<double, 3> next{p[0] + v[0] * in.Ts_s, p[1] + v[1] * in.Ts_s, p[2] + v[2] * in.Ts_s};
    if (!swept_once_) {
      out.removed_mm3 += sweep(p, p);
      swept_once_ = true;
      last_ = p;
    }
    // The process's schedule of stock updates (process/milling_process.cpp):
    // every two cells of travel, or a descent of 0.1 um. The stock lags the
    // tool by up to that much by design; with another schedule the two stocks
    // would differ at the run's end by where each last caught up.
    if (std::hypot(next[0] - last_[0], next[1] - last_[1]) >= 2.0 * stock_.cell_mm || next[2] < last_[2] - 1e-4) {
      out.removed_mm3 += sweep(last_, next);
      last_ = next;
    }
    return out;
  }

  /// Largest difference of a cell's top from `other`'s top at the cell's centre.
  double max_top_difference_mm(const HeightMapStock& other) const {
    double worst = 0.0;
    for (std::size_t iy = 0; iy < ny_; ++iy)
      for (std::size_t ix = 0; ix < nx_; ++ix)
        worst = std::max(worst, std::abs(static_cast<double>(top_[iy * nx_ + ix]) -
                                         other.top_z_at_mm(centre_x(ix), centre_y(iy))));
    return worst;
  }

 private:
  struct Element {
    double z_lo, z_hi, k_lo, k_hi;   // height span above the tip, and kappa span (corner)
    bool corner;
    double z, kappa, radius, db;     // evaluation point, edge radius there, chip width
  };
  struct Sample {
    std::array<double, 3> F{};   // on the tool
    double T_Nm{0.0};
    double chip{0.0};
  };

  double R() const { return 0.5 * tool_.diameter_mm; }

  void build_elements() {
    const double r = tool_.corner_radius_mm;
    if (r > 0.0) {
      const int n = std::max(1, static_cast<int>(std::ceil(0.5 * kPiRef * r / opt_.dz_mm)));
      for (int i = 0; i < n; ++i) {
        const double k0 = 0.5 * kPiRef * i / n, k1 = 0.5 * kPiRef * (i + 1) / n;
        const double km = 0.5 * (k0 + k1);
        elements_.push_back({r * (1 - std::cos(k0)), r * (1 - std::cos(k1)), k0, k1, true, r * (1 - std::cos(km)), km,
                             R() - r + r * std::sin(km), r * (k1 - k0)});
      }
    }
    for (double z0 = r; z0 < tool_.flute_length_mm - 1e-9 * opt_.dz_mm; z0 += opt_.dz_mm) {
      const double z1 = std::min(z0 + opt_.dz_mm, tool_.flute_length_mm);
      elements_.push_back({z0, z1, 0.0, 0.0, false, 0.5 * (z0 + z1), 0.5 * kPiRef, R(), z1 - z0});
    }
  }

  // Runout radius of flute j at height z, less R.
  double dR(int j, double z) const {
    const double lag = z * std::tan(tool_.helix_deg * kPiRef / 180.0) / R();
    return tool_.runout_rho_mm *
           std::cos(tool_.runout_lambda_deg * kPiRef / 180.0 - j * 2.0 * kPiRef / tool_.flutes + lag);
  }

  static double K(const ExpCoefficient& c, double h) { return c.a_N_per_mm2 + c.b_N_per_mm2 * std::exp(-c.c_per_mm * h); }

  Sample force(double phi, const std::array<double, 3>& p, const std::array<double, 2>& f) const {
    Sample out;
    const int N = tool_.flutes;
    const double z_top = stock_.top_z_mm - p[2];
    const double tan_helix = std::tan(tool_.helix_deg * kPiRef / 180.0);
    for (const Element& e : elements_) {
      if (e.z_lo >= z_top) break;
      // Part of the element below the stock top (in kappa on the corner, in z on the flank).
      double w = 1.0;
      if (z_top < e.z_hi) {
        if (e.corner) {
          const double k_top = std::acos(std::clamp(1.0 - z_top / tool_.corner_radius_mm, -1.0, 1.0));
          w = std::clamp((k_top - e.k_lo) / (e.k_hi - e.k_lo), 0.0, 1.0);
        } else {
          w = (z_top - e.z_lo) / (e.z_hi - e.z_lo);
        }
      }
      if (!(w > 0.0)) break;
      const double z_probe = p[2] + (w < 1.0 ? 0.5 * (e.z_lo + z_top) : e.z);
      for (int j = 0; j < N; ++j) {
        const double phij = phi + j * 2.0 * kPiRef / N - e.z * tan_helix / R();
        const double s = std::sin(phij), c = std::cos(phij);
        double hr = f[0] * s + f[1] * c;
        if (tool_.runout_rho_mm > 0.0) {
          double best = 1e300;
          for (int m = 1; m <= N; ++m) best = std::min(best, m * (f[0] * s + f[1] * c) + dR(j, e.z) - dR(j - m, e.z));
          hr = best;
        }
        const double h = hr * std::cos(lead_) * std::sin(e.kappa) - std::hypot(f[0], f[1]) * std::sin(lead_) * std::cos(e.kappa);
        if (!(h > 0.0)) continue;
        const double rj = e.radius + dR(j, e.z);
        const double probe = rj + stock_.cell_mm;
        if (!material(p[0] + probe * s, p[1] + probe * c, z_probe)) continue;
        const double db = w * e.db;
        const double Ft = (K(k_.Kt, h) * h + k_.Kte_N_per_mm) * db;
        const double Fr = (K(k_.Kr, h) * h + k_.Kre_N_per_mm) * db;
        const double Fa = (K(k_.Ka, h) * h + k_.Kae_N_per_mm) * db;
        const double sk = std::sin(e.kappa), ck = std::cos(e.kappa);
        out.F[0] += -Ft * c - Fr * sk * s + Fa * ck * s;
        out.F[1] += Ft * s - Fr * sk * c + Fa * ck * c;
        out.F[2] += Fr * ck + Fa * sk;
        out.T_Nm += Ft * rj * 1e-3;
        out.chip = std::max(out.chip, h);
      }
    }
    return out;
  }

  double engagement(const std::array<double, 3>& p, const std::array<double, 2>& dir) const {
    const double depth = std::min(stock_.top_z_mm - p[2], tool_.flute_length_mm);
    const double z = std::min((std::floor(std::max(0.5 * depth, 0.0) / opt_.dz_mm) + 0.5) * opt_.dz_mm, elements_.back().z);
    const double r = tool_.corner_radius_mm;
    const double edge = z >= r ? R() : R() - r + std::sqrt(std::max(r * r - (r - z) * (r - z), 0.0));
    const int n = static_cast<int>(std::lround(360.0 / opt_.engagement_step_deg));
    int hits = 0;
    for (int i = 0; i < n; ++i) {
      const double a = (i + 0.5) * 2.0 * kPiRef / n;
      if (dir[0] * std::sin(a) + dir[1] * std::cos(a) <= 0.0) continue;
      if (material(p[0] + (edge + stock_.cell_mm) * std::sin(a), p[1] + (edge + stock_.cell_mm) * std::cos(a), p[2] + z))
        ++hits;
    }
    return hits * 360.0 / n;
  }

  // --- the stock: a grid of cell tops over the outline's bounding box ---
  void build_stock() {
    double x1 = -1e300, y1 = -1e300;
    x0_ = y0_ = 1e300;
    for (const auto& q : stock_.outline_mm) {
      x0_ = std::min(x0_, q.x_mm);
      y0_ = std::min(y0_, q.y_mm);
      x1 = std::max(x1, q.x_mm);
      y1 = std::max(y1, q.y_mm);
    }
    nx_ = static_cast<std::size_t>(std::ceil((x1 - x0_) / stock_.cell_mm));
    ny_ = static_cast<std::size_t>(std::ceil((y1 - y0_) / stock_.cell_mm));
    top_.assign(nx_ * ny_, static_cast<float>(stock_.bottom_z_mm));
    for (std::size_t iy = 0; iy < ny_; ++iy)
      for (std::size_t ix = 0; ix < nx_; ++ix) {
        const double x = centre_x(ix), y = centre_y(iy);
        if (!inside(stock_.outline_mm, x, y)) continue;
        double t = stock_.top_z_mm;
        for (const auto& pk : stock_.pockets) {
          const bool in = pk.polygon_mm.size() >= 3 ? inside(pk.polygon_mm, x, y)
                                                    : std::hypot(x - pk.center_mm.x_mm, y - pk.center_mm.y_mm) < pk.radius_mm;
          if (in) t = std::min(t, std::max(pk.floor_z_mm, stock_.bottom_z_mm));
        }
        top_[iy * nx_ + ix] = static_cast<float>(t);
      }
  }
  // Even-odd rule.
  static bool inside(const std::vector<Point2>& poly, double x, double y) {
    bool in = false;
    for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
      const Point2& a = poly[i];
      const Point2& b = poly[j];
      if ((a.y_mm <= y) != (b.y_mm <= y) && x < a.x_mm + (y - a.y_mm) / (b.y_mm - a.y_mm) * (b.x_mm - a.x_mm)) in = !in;
    }
    return in;
  }
  double centre_x(std::size_t ix) const { return x0_ + (static_cast<double>(ix) + 0.5) * stock_.cell_mm; }
  double centre_y(std::size_t iy) const { return y0_ + (static_cast<double>(iy) + 0.5) * stock_.cell_mm; }
  bool material(double x, double y, double z) const {
    const double fx = std::floor((x - x0_) / stock_.cell_mm), fy = std::floor((y - y0_) / stock_.cell_mm);
    if (fx < 0 || fy < 0 || fx >= static_cast<double>(nx_) || fy >= static_cast<double>(ny_)) return false;
    return z > stock_.bottom_z_mm && z < top_[static_cast<std::size_t>(fy) * nx_ + static_cast<std::size_t>(fx)];
  }
  // Height of the tool's end at distance d from its axis (flat core, then the corner arc).
  double bottom_height(double d) const {
    const double r = tool_.corner_radius_mm, Rc = R() - r;
    if (d <= Rc) return 0.0;
    return r - std::sqrt(std::max(r * r - (d - Rc) * (d - Rc), 0.0));
  }
  // Every cell within R of the segment p0 p1 is lowered to the tool's end there.
  double sweep(const std::array<double, 3>& p0, const std::array<double, 3>& p1) {
    const double Dx = p1[0] - p0[0], Dy = p1[1] - p0[1], L2 = Dx * Dx + Dy * Dy;
    const auto index = [&](double v, double o) { return static_cast<long>(std::floor((v - o) / stock_.cell_mm)); };
    const long ix0 = std::max(0L, index(std::min(p0[0], p1[0]) - R(), x0_) - 1);
    const long ix1 = std::min(static_cast<long>(nx_) - 1, index(std::max(p0[0], p1[0]) + R(), x0_) + 1);
    const long iy0 = std::max(0L, index(std::min(p0[1], p1[1]) - R(), y0_) - 1);
    const long iy1 = std::min(static_cast<long>(ny_) - 1, index(std::max(p0[1], p1[1]) + R(), y0_) + 1);
    double removed = 0.0;
    for (long iy = iy0; iy <= iy1; ++iy)
      for (long ix = ix0; ix <= ix1; ++ix) {
        const double x = centre_x(static_cast<std::size_t>(ix)), y = centre_y(static_cast<std::size_t>(iy));
        const double s = L2 > 0.0 ? std::clamp(((x - p0[0]) * Dx + (y - p0[1]) * Dy) / L2, 0.0, 1.0) : 0.0;
        const double ex = x - (p0[0] + s * Dx), ey = y - (p0[1] + s * Dy);
        const double d = std::sqrt(ex * ex + ey * ey);
        if (d > R()) continue;
        float& top = top_[static_cast<std::size_t>(iy) * nx_ + static_cast<std::size_t>(ix)];
        const double z = std::max(p0[2] + s * (p1[2] - p0[2]) + bottom_height(d), stock_.bottom_z_mm);
        if (z < top) {
          removed += top - z;
          top = static_cast<float>(z);
        }
      }
    return removed * stock_.cell_mm * stock_.cell_mm;
  }

  ToolGeometry tool_;
  CuttingCoefficients k_;
  ForceModelOptions opt_;
  StockSpec stock_;
  double phi_;
  double lead_;
  std::vector<Element> elements_;
  double x0_{0.0}, y0_{0.0};
  std::size_t nx_{0}, ny_{0};
  std::vector<float> top_;
  bool swept_once_{false};
  std::array<double, 3> last_{};
};

ProcessSetup scenario_setup(const char* name) {
  const auto file = std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios" / name / "scenario.yaml";
  return io::parse_process_setup(io::load_yaml_file(file)["process"], file.string(), file.parent_path());
}

struct Worst {
  double force_N{0.0};     // largest force difference, any component, F_avg or F_N
  double peak_N{0.0};      // largest force magnitude component seen
  double torque_Nm{0.0};
  double chip_mm{0.0};
  double engagement_deg{0.0};
  double removed_rel{0.0};
  double top_mm{0.0};      // largest difference of a cell's top at the end
  int cutting_ticks{0};
};

// Ticks along `path` (tip positions, mm) at `speed` mm/s with a +-3 % ripple
// of the speed (the drives' feed is never exact), slowing to a tenth within
// 0.5 mm of each point where the path turns in xy; both models take the same
// inputs.
Worst run_both(const ProcessSetup& setup, double rpm, const std::vector<std::array<double, 3>>& path, double speed,
               const std::array<double, 3>& precut_from) {
  MillingProcess fast(setup);
  ReferenceProcess ref(setup);
  fast.remove_swept(precut_from, path.front());
  ref.remove_swept(precut_from, path.front());
  Worst w;
  ProcessInput in;
  in.Ts_s = 1e-4;
  in.spindle_rpm = rpm;
  double removed_fast = 0.0, removed_ref = 0.0;
  std::int64_t k = 0;
  for (std::size_t seg = 1; seg < path.size(); ++seg) {
    const auto a = path[seg - 1], b = path[seg];
    const double L = std::hypot(b[0] - a[0], b[1] - a[1], b[2] - a[2]);
    const std::array<double, 3> u{(b[0] - a[0]) / L, (b[1] - a[1]) / L, (b[2] - a[2]) / L};
    const auto turns = [&](std::size_t i) {   // the path turns in xy at point i
      if (i == 0 || i + 1 >= path.size()) return false;
      const auto &p = path[i - 1], &q = path[i], &r = path[i + 1];
      return std::abs((q[0] - p[0]) * (r[1] - q[1]) - (q[1] - p[1]) * (r[0] - q[0])) > 1e-9;
    };
    const bool slow_start = turns(seg - 1), slow_end = turns(seg);
    double s = 0.0;
    while (s < L) {
      const double to_corner = std::min(slow_start ? s : 1e300, slow_end ? L - s : 1e300);
      const double v = speed * (1.0 + 0.03 * std::sin(2.0 * kPiRef * 13.0 * k * in.Ts_s)) *
                       std::clamp(to_corner / 0.5, 0.1, 1.0);
      in.k = k;
      in.t_s = k * in.Ts_s;
      in.p_mm = {a[0] + s * u[0], a[1] + s * u[1], a[2] + s * u[2]};
      in.v_mm_per_s = {v * u[0], v * u[1], v * u[2]};
      const ProcessOutput o = fast.step(in);
      const ProcessOutput r = ref.step(in);
      for (int i = 0; i < 3; ++i) {
        w.force_N = std::max({w.force_N, std::abs(o.F_avg_N[i] - r.F_avg_N[i]), std::abs(o.F_N[i] - r.F_N[i])});
        w.peak_N = std::max(w.peak_N, std::abs(r.F_N[i]));
      }
      w.torque_Nm = std::max(w.torque_Nm, std::abs(o.spindle_torque_Nm - r.spindle_torque_Nm));
      w.chip_mm = std::max(w.chip_mm, std::abs(o.chip_mm - r.chip_mm));
      w.engagement_deg = std::max(w.engagement_deg, std::abs(o.engagement_deg - r.engagement_deg));
      if (r.chip_mm > 0.0) ++w.cutting_ticks;
      removed_fast += o.removed_mm3;
      removed_ref += r.removed_mm3;
      s += v * in.Ts_s;
      ++k;
    }
  }
  w.removed_rel = std::abs(removed_fast - removed_ref) / std::max(removed_ref, 1e-300);
  w.top_mm = ref.max_top_difference_mm(fast.stock());
  std::printf("ticks %lld, cutting %d, peak %.1f N: max |dF| %.3g N, |dT| %.3g Nm, |dchip| %.3g mm, |deng| %.3g deg, "
              "removed %.4f mm^3 (rel diff %.2g), cell tops differ by %.3g mm at most\n",
              static_cast<long long>(k), w.cutting_ticks, w.peak_N, w.force_N, w.torque_Nm, w.chip_mm,
              w.engagement_deg, removed_ref, w.removed_rel, w.top_mm);
  return w;
}

void expect_rounding_only(const Worst& w, int min_cutting_ticks) {
  EXPECT_GT(w.cutting_ticks, min_cutting_ticks);   // the comparison covers a real cut
  EXPECT_GT(w.peak_N, 50.0);
  EXPECT_LE(w.force_N, 1e-9 * w.peak_N);
  EXPECT_LE(w.torque_Nm, 1e-9 * w.peak_N * 1e-2);   // a 10 mm lever at most: the same bound in N m
  EXPECT_LE(w.chip_mm, 1e-12);
  EXPECT_EQ(w.engagement_deg, 0.0);
  EXPECT_EQ(w.top_mm, 0.0);
  EXPECT_LE(w.removed_rel, 1e-6);
}

// The default scenario (FADAL pocket corner, Duan's bull-nose cutter and
// chip-dependent coefficients at 1200 rpm, ap 1 mm, ae 2 mm): the last 6 mm
// of the wall cut, into the inner corner, and 6 mm out along the second wall.
// The tip drops 2 um and rises 1 um on the way (the z drive is not exact
// either), so the stock takes both its crescent and its whole-sweep updates.
TEST(ProcessReference, DefaultScenarioCornerMatchesPlainEvaluation) {
  const ProcessSetup setup = scenario_setup("fadal_pocket_corner");
  ASSERT_GT(setup.tool.corner_radius_mm, 0.0);
  ASSERT_NE(setup.coefficients.Kt.b_N_per_mm2, 0.0);   // K depends on h here
  const std::vector<std::array<double, 3>> path{
      {-11, -5, -1}, {-8, -5, -1}, {-7, -5, -1.002}, {-5, -5, -1.002}, {-5, -8, -1.001}, {-5, -11, -1.001}};
  expect_rounding_only(run_both(setup, 1200, path, 500.0 / 60.0, {-45, -5, -1}), 6000);
}

// The same cut with Duan's lead of 10 deg (eq. 4 with its own coefficient set, eq. 20).
TEST(ProcessReference, DefaultScenarioWithLeadMatchesPlainEvaluation) {
  ProcessSetup setup = scenario_setup("fadal_pocket_corner");
  setup.lead_deg = 10.0;
  setup.coefficients = io::load_material_file(
      std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios/materials/al2024_t6_duan2025.yaml", 10.0, 0.0);
  const std::vector<std::array<double, 3>> path{{-9, -5, -1}, {-5, -5, -1}, {-5, -9, -1}};
  expect_rounding_only(run_both(setup, 1200, path, 500.0 / 60.0, {-45, -5, -1}), 4000);
}

// aluminium_hsm's flat 3-flute cutter at 12000 rpm (five force samples per
// tick) with 6 um of runout (the Kline-DeVor minimum over earlier flutes):
// a side cut ae 3 mm, ap 6 mm into its inner corner and out.
TEST(ProcessReference, HighSpeedCornerWithRunoutMatchesPlainEvaluation) {
  ProcessSetup setup = scenario_setup("aluminium_hsm");
  setup.tool.runout_rho_mm = 0.006;
  setup.tool.runout_lambda_deg = 35.0;
  const std::vector<std::array<double, 3>> path{{-14, -6, -6}, {-6, -6, -6}, {-6, -14, -6}};
  expect_rounding_only(run_both(setup, 12000, path, 3600.0 / 60.0, {-60, -6, -6}), 2500);
}

}  // namespace
}  // namespace twin::process
