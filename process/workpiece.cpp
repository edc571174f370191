#include "process/workpiece.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define TWIN_PROCESS_AVX 1
#include <immintrin.h>
#else
#define TWIN_PROCESS_AVX 0
#endif

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::process {
namespace {

constexpr double kMaxCells = 80e6;

/// x where the row at height y crosses the polygon's edges (even-odd rule).
std::vector<double> row_crossings(const std::vector<Point2>& poly, double y) {
  std::vector<double> xs;
  const std::size_t n = poly.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& a = poly[i];
    const Point2& b = poly[(i + 1) % n];
    if ((a.y_mm <= y) != (b.y_mm <= y)) xs.push_back(a.x_mm + (y - a.y_mm) / (b.y_mm - a.y_mm) * (b.x_mm - a.x_mm));
  }
  std::sort(xs.begin(), xs.end());
  return xs;
}

}  // namespace

std::vector<Point2> StockSpec::rectangle(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

void StockSpec::validate(const std::string& where) const {
  if (outline_mm.size() < 3)
    throw ConfigError(fmt::format("{}: stock.outline_mm has {} points, needs at least 3", where, outline_mm.size()));
  for (const auto& p : outline_mm)
    if (!std::isfinite(p.x_mm) || !std::isfinite(p.y_mm))
      throw ConfigError(fmt::format("{}: stock.outline_mm has a non-finite point", where));
  if (!std::isfinite(top_z_mm) || !std::isfinite(bottom_z_mm) || top_z_mm <= bottom_z_mm)
    throw ConfigError(fmt::format("{}: stock.top_z_mm = {} must be above stock.bottom_z_mm = {}", where, top_z_mm, bottom_z_mm));
  if (!(cell_mm >= 0.005 && cell_mm <= 1.0))
    throw ConfigError(fmt::format("{}: stock.cell_mm = {} must be in [0.005, 1] mm", where, cell_mm));
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (const auto& p : outline_mm) {
    xmin = std::min(xmin, p.x_mm);
    xmax = std::max(xmax, p.x_mm);
    ymin = std::min(ymin, p.y_mm);
    ymax = std::max(ymax, p.y_mm);
  }
  const double cells = std::ceil((xmax - xmin) / cell_mm) * std::ceil((ymax - ymin) / cell_mm);
  if (!(xmax > xmin && ymax > ymin)) throw ConfigError(fmt::format("{}: stock.outline_mm encloses no area", where));
  if (cells > kMaxCells)
    throw ConfigError(fmt::format("{}: stock of {:.1f} x {:.1f} mm at stock.cell_mm = {} needs {:.3g} cells (limit {:.3g}); "
                                  "use a larger cell",
                                  where, xmax - xmin, ymax - ymin, cell_mm, cells, kMaxCells));
  for (std::size_t i = 0; i < pockets.size(); ++i) {
    const auto& pk = pockets[i];
    if (!std::isfinite(pk.floor_z_mm))
      throw ConfigError(fmt::format("{}: stock.pockets[{}].floor_z_mm is not finite", where, i));
    if (pk.polygon_mm.empty() && !(pk.radius_mm > 0.0 && std::isfinite(pk.radius_mm)))
      throw ConfigError(fmt::format("{}: stock.pockets[{}] needs polygon_mm (>= 3 points) or radius_mm > 0", where, i));
    if (!pk.polygon_mm.empty() && pk.polygon_mm.size() < 3)
      throw ConfigError(fmt::format("{}: stock.pockets[{}].polygon_mm has {} points, needs at least 3", where, i,
                                    pk.polygon_mm.size()));
  }
}

HeightMapStock::HeightMapStock(const StockSpec& spec) {
  spec.validate("stock");
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (const auto& p : spec.outline_mm) {
    xmin = std::min(xmin, p.x_mm);
    xmax = std::max(xmax, p.x_mm);
    ymin = std::min(ymin, p.y_mm);
    ymax = std::max(ymax, p.y_mm);
  }
  cell_mm_ = spec.cell_mm;
  inv_cell_ = 1.0 / cell_mm_;
  x0_mm_ = xmin;
  y0_mm_ = ymin;
  nx_ = static_cast<std::size_t>(std::ceil((xmax - xmin) / cell_mm_));
  ny_ = static_cast<std::size_t>(std::ceil((ymax - ymin) / cell_mm_));
  top_z_mm_ = spec.top_z_mm;
  bottom_z_mm_ = spec.bottom_z_mm;
  top_.assign(nx_ * ny_, static_cast<float>(bottom_z_mm_));
  auto fill = [&](const std::vector<Point2>& poly, auto&& set) {
    for (std::size_t iy = 0; iy < ny_; ++iy) {
      const double y = y0_mm_ + (static_cast<double>(iy) + 0.5) * cell_mm_;
      const auto xs = row_crossings(poly, y);
      for (std::size_t k = 0; k + 1 < xs.size(); k += 2) {
        const double a = std::ceil((xs[k] - x0_mm_) * inv_cell_ - 0.5);
        const double b = std::floor((xs[k + 1] - x0_mm_) * inv_cell_ - 0.5);
        for (double ix = std::max(a, 0.0); ix <= std::min(b, static_cast<double>(nx_) - 1.0); ix += 1.0)
          set(top_[iy * nx_ + static_cast<std::size_t>(ix)]);
      }
    }
  };
  fill(spec.outline_mm, [&](float& t) { t = static_cast<float>(top_z_mm_); });
  for (const auto& pk : spec.pockets) {
    const float floor_z = static_cast<float>(std::max(pk.floor_z_mm, bottom_z_mm_));
    if (pk.polygon_mm.size() >= 3) {
      fill(pk.polygon_mm, [&](float& t) { t = std::min(t, floor_z); });
    } else {
      for (std::size_t iy = 0; iy < ny_; ++iy) {
        const double dy = y0_mm_ + (static_cast<double>(iy) + 0.5) * cell_mm_ - pk.center_mm.y_mm;
        if (std::abs(dy) >= pk.radius_mm) continue;
        const double w = std::sqrt(pk.radius_mm * pk.radius_mm - dy * dy);
        const double a = std::ceil((pk.center_mm.x_mm - w - x0_mm_) * inv_cell_ - 0.5);
        const double b = std::floor((pk.center_mm.x_mm + w - x0_mm_) * inv_cell_ - 0.5);
        for (double ix = std::max(a, 0.0); ix <= std::min(b, static_cast<double>(nx_) - 1.0); ix += 1.0) {
          float& t = top_[iy * nx_ + static_cast<std::size_t>(ix)];
          t = std::min(t, floor_z);
        }
      }
    }
  }
  refresh_block_max();
#if TWIN_PROCESS_AVX
  use_avx_ = __builtin_cpu_supports("avx");
#endif
}

void HeightMapStock::refresh_block_max() {
  blocks_per_row_ = (nx_ + kBlock - 1) / kBlock;
  block_max_.assign(blocks_per_row_ * ny_, static_cast<float>(bottom_z_mm_));
  for (std::size_t iy = 0; iy < ny_; ++iy)
    for (std::size_t ix = 0; ix < nx_; ++ix) {
      float& m = block_max_[iy * blocks_per_row_ + ix / kBlock];
      m = std::max(m, top_[iy * nx_ + ix]);
    }
}

int HeightMapStock::count_in_material(double cx_mm, double cy_mm, double r_mm, const double* s, const double* c,
                                      std::size_t n, double z_mm) const noexcept {
  if (!(z_mm > bottom_z_mm_)) return 0;
  int hits = 0;
  std::size_t i = 0;
#if defined(__SSE2__)
  // cell_at's arithmetic; fx < nx is floor(fx) < nx for fx >= 0.
  const double nx = static_cast<double>(nx_), ny = static_cast<double>(ny_);
  // Two points at a time. The cell index iy nx + ix is formed in doubles
  // (exact: below 2^31 cells) and converted once.
  const __m128d vcx = _mm_set1_pd(cx_mm), vcy = _mm_set1_pd(cy_mm), vr = _mm_set1_pd(r_mm),
                vx0 = _mm_set1_pd(x0_mm_), vy0 = _mm_set1_pd(y0_mm_), vinv = _mm_set1_pd(inv_cell_),
                vnx = _mm_set1_pd(nx), vny = _mm_set1_pd(ny), vz = _mm_set1_pd(z_mm), zero = _mm_setzero_pd();
  for (; i + 2 <= n; i += 2) {
    const __m128d fx = _mm_mul_pd(_mm_sub_pd(_mm_add_pd(vcx, _mm_mul_pd(vr, _mm_loadu_pd(s + i))), vx0), vinv);
    const __m128d fy = _mm_mul_pd(_mm_sub_pd(_mm_add_pd(vcy, _mm_mul_pd(vr, _mm_loadu_pd(c + i))), vy0), vinv);
    const __m128d in = _mm_and_pd(_mm_and_pd(_mm_cmpge_pd(fx, zero), _mm_cmpge_pd(fy, zero)),
                                  _mm_and_pd(_mm_cmplt_pd(fx, vnx), _mm_cmplt_pd(fy, vny)));
    const int in_mask = _mm_movemask_pd(in);
    if (in_mask == 0) continue;
    const __m128i ix = _mm_cvttpd_epi32(_mm_and_pd(in, fx));
    const __m128i iy = _mm_cvttpd_epi32(_mm_and_pd(in, fy));
    const __m128i cell = _mm_cvttpd_epi32(_mm_add_pd(_mm_mul_pd(_mm_cvtepi32_pd(iy), vnx), _mm_cvtepi32_pd(ix)));
    const auto c0 = static_cast<std::size_t>(_mm_cvtsi128_si32(cell));
    const auto c1 = static_cast<std::size_t>(_mm_cvtsi128_si32(_mm_shuffle_epi32(cell, 1)));
    const __m128d top = _mm_cvtps_pd(_mm_set_ps(0.0f, 0.0f, top_[c1], top_[c0]));
    const int hit_mask = in_mask & _mm_movemask_pd(_mm_cmplt_pd(vz, top));
    hits += (hit_mask & 1) + (hit_mask >> 1);
  }
#endif
  for (; i < n; ++i) {
    const std::size_t cell = cell_at(cx_mm + r_mm * s[i], cy_mm + r_mm * c[i]);
    if (cell != kNoCell) hits += z_mm < static_cast<double>(top_[cell]) ? 1 : 0;
  }
  return hits;
}

double HeightMapStock::top_z_at_mm(double x_mm, double y_mm) const noexcept {
  const std::size_t cell = cell_at(x_mm, y_mm);
  return cell == kNoCell ? bottom_z_mm_ : static_cast<double>(top_[cell]);
}

double HeightMapStock::volume_mm3() const {
  double v = 0.0;
  for (float t : top_) v += std::max(static_cast<double>(t) - bottom_z_mm_, 0.0);
  return v * cell_mm_ * cell_mm_;
}

HeightMapStock::SweepCut HeightMapStock::make_cut(const ToolGeometry& tool, const std::array<double, 3>& p0,
                                                  const std::array<double, 3>& p1) const {
  SweepCut c{};
  c.R_mm = tool.radius_mm();
  c.R2_mm2 = c.R_mm * c.R_mm;
  c.r_mm = tool.corner_radius_mm;
  c.Rc_mm = c.R_mm - c.r_mm;
  c.r2_mm2 = c.r_mm * c.r_mm;
  c.p0x_mm = p0[0];
  c.p0y_mm = p0[1];
  c.p0z_mm = p0[2];
  c.Dx_mm = p1[0] - p0[0];
  c.Dy_mm = p1[1] - p0[1];
  c.Dz_mm = p1[2] - p0[2];
  const double L2 = c.Dx_mm * c.Dx_mm + c.Dy_mm * c.Dy_mm;
  c.inv_L2_per_mm2 = L2 > 0.0 ? 1.0 / L2 : 0.0;
  // A cell is cut to p0z + s Dz + bottom_height >= min(p0z, p1z) less a few
  // ulps of the tip height (bottom_height >= 0); 1e-9 mm covers those ulps
  // for any height below 1e5 mm.
  c.z_skip_mm = std::max(bottom_z_mm_, std::min(p0[2], p1[2]) - 1e-9);
  return c;
}

namespace {

// Two cells at a time: SSE2 on x86-64, else two scalars. Every operation is a
// correctly rounded IEEE one (no fused multiply-add), so a pair gives the
// same bits as the scalar expression in the same order.
#if defined(__SSE2__)
struct Pair {
  __m128d v;
};
inline Pair pair(double a, double b) { return {_mm_set_pd(b, a)}; }
inline Pair splat(double a) { return {_mm_set1_pd(a)}; }
inline Pair operator+(Pair a, Pair b) { return {_mm_add_pd(a.v, b.v)}; }
inline Pair operator-(Pair a, Pair b) { return {_mm_sub_pd(a.v, b.v)}; }
inline Pair operator*(Pair a, Pair b) { return {_mm_mul_pd(a.v, b.v)}; }
inline Pair sqrt_of(Pair a) { return {_mm_sqrt_pd(a.v)}; }
inline Pair max_of(Pair a, Pair b) { return {_mm_max_pd(a.v, b.v)}; }
inline Pair min_of(Pair a, Pair b) { return {_mm_min_pd(a.v, b.v)}; }
/// a > b ? x : y, per lane.
inline Pair select_gt(Pair a, Pair b, Pair x, Pair y) {
  const __m128d m = _mm_cmpgt_pd(a.v, b.v);
  return {_mm_or_pd(_mm_and_pd(m, x.v), _mm_andnot_pd(m, y.v))};
}
inline void store(Pair a, double* out) { _mm_storeu_pd(out, a.v); }
#else
struct Pair {
  double v[2];
};
inline Pair pair(double a, double b) { return {{a, b}}; }
inline Pair splat(double a) { return {{a, a}}; }
inline Pair operator+(Pair a, Pair b) { return {{a.v[0] + b.v[0], a.v[1] + b.v[1]}}; }
inline Pair operator-(Pair a, Pair b) { return {{a.v[0] - b.v[0], a.v[1] - b.v[1]}}; }
inline Pair operator*(Pair a, Pair b) { return {{a.v[0] * b.v[0], a.v[1] * b.v[1]}}; }
inline Pair sqrt_of(Pair a) { return {{std::sqrt(a.v[0]), std::sqrt(a.v[1])}}; }
inline Pair max_of(Pair a, Pair b) { return {{std::max(a.v[0], b.v[0]), std::max(a.v[1], b.v[1])}}; }
inline Pair min_of(Pair a, Pair b) { return {{std::min(a.v[0], b.v[0]), std::min(a.v[1], b.v[1])}}; }
inline Pair select_gt(Pair a, Pair b, Pair x, Pair y) {
  return {{a.v[0] > b.v[0] ? x.v[0] : y.v[0], a.v[1] > b.v[1] ? x.v[1] : y.v[1]}};
}
inline void store(Pair a, double* out) {
  out[0] = a.v[0];
  out[1] = a.v[1];
}
#endif

}  // namespace

// The height a cell is cut to: ToolGeometry::bottom_height_mm at the cell
// centre's distance from the swept axis, written out in the same order (the
// heights are the same to the last bit); +inf beyond the tool's radius.
void HeightMapStock::cut_heights(const SweepCut& c, double y, std::size_t ix, std::size_t n, double* out) const {
  const Pair p0x = splat(c.p0x_mm), p0y = splat(c.p0y_mm), p0z = splat(c.p0z_mm), Dx = splat(c.Dx_mm),
             Dy = splat(c.Dy_mm), Dz = splat(c.Dz_mm), inv_L2 = splat(c.inv_L2_per_mm2), R2 = splat(c.R2_mm2),
             Rc = splat(c.Rc_mm), r = splat(c.r_mm), r2 = splat(c.r2_mm2), yy = splat(y),
             ty = splat((y - c.p0y_mm) * c.Dy_mm), zero = splat(0.0), one = splat(1.0),
             inf = splat(std::numeric_limits<double>::infinity());
  for (std::size_t k = 0; k < n; k += 2) {
    const double xi = static_cast<double>(ix + k);
    const Pair x = pair(x0_mm_ + (xi + 0.5) * cell_mm_, x0_mm_ + (xi + 1.5) * cell_mm_);
    const Pair s = min_of(max_of(((x - p0x) * Dx + ty) * inv_L2, zero), one);
    const Pair ex = x - (p0x + s * Dx);
    const Pair ey = yy - (p0y + s * Dy);
    const Pair d2 = ex * ex + ey * ey;
    const Pair d = sqrt_of(d2);
    const Pair u = d - Rc;
    const Pair bottom = select_gt(d, Rc, r - sqrt_of(max_of(r2 - u * u, zero)), zero);
    store(select_gt(d2, R2, inf, p0z + s * Dz + bottom), out + k);
  }
}

#if TWIN_PROCESS_AVX
// cut_heights four cells at a time: the same operations on 256-bit vectors
// (AVX has no fused multiply-add, so the same bits again; the cell centres
// ix + k + (j + 1/2) are exact sums of integers and halves).
__attribute__((target("avx"))) void HeightMapStock::cut_heights_avx(const SweepCut& c, double y, std::size_t ix,
                                                                    std::size_t n, double* out) const {
  const __m256d p0x = _mm256_set1_pd(c.p0x_mm), p0y = _mm256_set1_pd(c.p0y_mm), p0z = _mm256_set1_pd(c.p0z_mm),
                Dx = _mm256_set1_pd(c.Dx_mm), Dy = _mm256_set1_pd(c.Dy_mm), Dz = _mm256_set1_pd(c.Dz_mm),
                inv_L2 = _mm256_set1_pd(c.inv_L2_per_mm2), R2 = _mm256_set1_pd(c.R2_mm2), Rc = _mm256_set1_pd(c.Rc_mm),
                r = _mm256_set1_pd(c.r_mm), r2 = _mm256_set1_pd(c.r2_mm2), yy = _mm256_set1_pd(y),
                ty = _mm256_set1_pd((y - c.p0y_mm) * c.Dy_mm), zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0),
                inf = _mm256_set1_pd(std::numeric_limits<double>::infinity()), x0 = _mm256_set1_pd(x0_mm_),
                cell = _mm256_set1_pd(cell_mm_), lane_half = _mm256_set_pd(3.5, 2.5, 1.5, 0.5);
  for (std::size_t k = 0; k < n; k += 4) {
    const __m256d x = _mm256_add_pd(
        x0, _mm256_mul_pd(_mm256_add_pd(_mm256_set1_pd(static_cast<double>(ix + k)), lane_half), cell));
    const __m256d s = _mm256_min_pd(
        _mm256_max_pd(_mm256_mul_pd(_mm256_add_pd(_mm256_mul_pd(_mm256_sub_pd(x, p0x), Dx), ty), inv_L2), zero), one);
    const __m256d ex = _mm256_sub_pd(x, _mm256_add_pd(p0x, _mm256_mul_pd(s, Dx)));
    const __m256d ey = _mm256_sub_pd(yy, _mm256_add_pd(p0y, _mm256_mul_pd(s, Dy)));
    const __m256d d2 = _mm256_add_pd(_mm256_mul_pd(ex, ex), _mm256_mul_pd(ey, ey));
    const __m256d d = _mm256_sqrt_pd(d2);
    const __m256d u = _mm256_sub_pd(d, Rc);
    const __m256d fillet =
        _mm256_sub_pd(r, _mm256_sqrt_pd(_mm256_max_pd(_mm256_sub_pd(r2, _mm256_mul_pd(u, u)), zero)));
    const __m256d bottom = _mm256_and_pd(_mm256_cmp_pd(d, Rc, _CMP_GT_OQ), fillet);
    const __m256d z = _mm256_add_pd(_mm256_add_pd(p0z, _mm256_mul_pd(s, Dz)), bottom);
    const __m256d beyond = _mm256_cmp_pd(d2, R2, _CMP_GT_OQ);
    _mm256_storeu_pd(out + k, _mm256_or_pd(_mm256_and_pd(beyond, inf), _mm256_andnot_pd(beyond, z)));
  }
}
#else
void HeightMapStock::cut_heights_avx(const SweepCut& c, double y, std::size_t ix, std::size_t n, double* out) const {
  cut_heights(c, y, ix, n, out);
}
#endif

void HeightMapStock::lower_cells_in_row(std::size_t iy, double xa, double xb, const SweepCut& c, double& removed) {
  const double a = std::max(std::ceil((xa - x0_mm_) * inv_cell_ - 0.5), 0.0);
  const double b = std::min(std::floor((xb - x0_mm_) * inv_cell_ - 0.5), static_cast<double>(nx_) - 1.0);
  if (a > b) return;
  const double y = y0_mm_ + (static_cast<double>(iy) + 0.5) * cell_mm_;
  const double z_skip = c.z_skip_mm, z_bottom = bottom_z_mm_;
  float* row = top_.data() + iy * nx_;
  float* block_max = block_max_.data() + iy * blocks_per_row_;
  const auto ia = static_cast<std::size_t>(a);
  const auto ib = static_cast<std::size_t>(b) + 1;
  double removed_row = removed;   // summed cell by cell in order, as one loop would
  constexpr std::size_t kChunk = 16 * kBlock;
  std::array<double, kChunk + 4> z_cut;
  for (std::size_t c0 = ia; c0 < ib; c0 += kChunk) {
    const std::size_t c1 = std::min(ib, c0 + kChunk);
    // The span of the chunk's blocks that may hold a cell above z_skip.
    std::size_t lo = c1, hi = c0;
    for (std::size_t blk = c0 / kBlock; blk * kBlock < c1; ++blk) {
      if (static_cast<double>(block_max[blk]) <= z_skip) continue;
      lo = std::min(lo, std::max(c0, blk * kBlock));
      hi = std::max(hi, std::min(c1, (blk + 1) * kBlock));
    }
    if (lo >= hi) continue;
    // First the heights of the whole span, several cells at a time and
    // without a branch (the square roots of successive cells overlap), then
    // the cells in order.
    if (use_avx_)
      cut_heights_avx(c, y, lo, hi - lo, z_cut.data());
    else
      cut_heights(c, y, lo, hi - lo, z_cut.data());
    for (std::size_t ix = lo; ix < hi; ++ix) {
      const double top = static_cast<double>(row[ix]);
      const double z_new = z_cut[ix - lo];
      if (top <= z_skip || z_new >= top) continue;
      const double z_set = std::max(z_new, z_bottom);
      removed_row += top - z_set;
      row[ix] = static_cast<float>(z_set);
    }
    // The visited blocks' highest tops, now exact again.
    for (std::size_t blk = lo / kBlock; blk * kBlock < hi; ++blk) {
      const std::size_t end = std::min(nx_, (blk + 1) * kBlock);
      float top_max = static_cast<float>(z_bottom);
      for (std::size_t ix = blk * kBlock; ix < end; ++ix) top_max = std::max(top_max, row[ix]);
      block_max[blk] = top_max;
    }
  }
  removed = removed_row;
}

double HeightMapStock::remove_sweep(const ToolGeometry& tool, const std::array<double, 3>& p0_mm,
                                    const std::array<double, 3>& p1_mm, bool whole) {
  const double R = tool.radius_mm();
  const double Rc = R - tool.corner_radius_mm;
  const double Dx = p1_mm[0] - p0_mm[0];
  const double Dy = p1_mm[1] - p0_mm[1];
  const double L = std::hypot(Dx, Dy);
  const bool incremental = !whole && p1_mm[2] >= p0_mm[2] - 1e-9 && L <= 3.0 * cell_mm_;
  if (incremental && L == 0.0) return 0.0;
  double removed = 0.0;
  const SweepCut cut = make_cut(tool, p0_mm, p1_mm);
  const double y_min = std::min(p0_mm[1], p1_mm[1]);
  const double y_max = std::max(p0_mm[1], p1_mm[1]);
  const double x_min = std::min(p0_mm[0], p1_mm[0]);
  const double x_max = std::max(p0_mm[0], p1_mm[0]);
  const double ia = std::max(std::ceil((y_min - R - y0_mm_) * inv_cell_ - 0.5), 0.0);
  const double ib = std::min(std::floor((y_max + R - y0_mm_) * inv_cell_ - 0.5), static_cast<double>(ny_) - 1.0);
  for (double fiy = ia; fiy <= ib; fiy += 1.0) {
    const auto iy = static_cast<std::size_t>(fiy);
    const double y = y0_mm_ + (fiy + 0.5) * cell_mm_;
    if (!incremental) {
      lower_cells_in_row(iy, x_min - R, x_max + R, cut, removed);
      continue;
    }
    // The row's cells within R of the segment lie within w of its x range.
    const double dy = y < y_min ? y_min - y : (y > y_max ? y - y_max : 0.0);
    if (dy > R) continue;
    const double w = std::sqrt(R * R - dy * dy);
    double xa = x_min - w;
    double xb = x_max + w;
    // A cell behind the line through p0 across the move is nearest to p0,
    // where the sweep before this one ended: it is already as low as this
    // move can cut it. Ahead of that line its distance from the segment is
    // shorter than from p0 (also between p0 and the bisector of p0 p1, beside
    // the path, where a rounded end cuts its fillet lower).
    if (Dx > 0.0) {
      xa = std::max(xa, p0_mm[0] - (y - p0_mm[1]) * Dy / Dx);
    } else if (Dx < 0.0) {
      xb = std::min(xb, p0_mm[0] - (y - p0_mm[1]) * Dy / Dx);
    } else if ((y - p0_mm[1]) * Dy < 0.0) {
      continue;
    }
    if (xa > xb) continue;
    // Cells over the flat core of the tool at p0 are already at the tip height.
    const double dy0 = y - p0_mm[1];
    if (Rc > 0.0 && std::abs(dy0) < Rc) {
      const double w0 = std::sqrt(Rc * Rc - dy0 * dy0);
      const double ca = p0_mm[0] - w0;
      const double cb = p0_mm[0] + w0;
      if (xa < ca) lower_cells_in_row(iy, xa, std::min(xb, ca), cut, removed);
      if (xb > cb) lower_cells_in_row(iy, std::max(xa, cb), xb, cut, removed);
    } else {
      lower_cells_in_row(iy, xa, xb, cut, removed);
    }
  }
  return removed * cell_mm_ * cell_mm_;
}

}  // namespace twin::process
