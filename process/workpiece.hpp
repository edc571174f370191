#pragma once
/// The in-process workpiece, 2.5D, as a height map.
///
/// The stock is a prism: a polygon outline in the xy plane between bottom_z
/// and top_z, minus pockets (polygons or circles down to a floor height).
/// A regular grid of square cells (cell_mm, ~0.02-0.05 mm) keeps per cell the
/// height of the remaining material's top face; material at (x, y, z) exists
/// when bottom_z < z < top(cell(x, y)). Every query is O(1).
///
/// The tool removes material as it sweeps: a cell whose centre lies at
/// distance d from the tool axis is cut down to z_tip + bottom_height(d)
/// (the tool's end profile: flat, bull-nose fillet or ball). A small move
/// touches only the cells it can lower (the crescent ahead of the tool and,
/// for a rounded end, the front half of the corner annulus), so the cost per
/// update does not grow with the removed region.
#include <array>
#include <string>
#include <vector>

#include "process/tool.hpp"

namespace twin::process {

struct Point2 {
  double x_mm{0.0};
  double y_mm{0.0};
};

/// A pocket already in the stock: a polygon (when polygon_mm has >= 3
/// points) or else a circle (centre, radius), down to floor_z_mm.
struct PocketFeature {
  std::vector<Point2> polygon_mm;
  Point2 center_mm{};
  double radius_mm{0.0};
  double floor_z_mm{0.0};
};

struct StockSpec {
  std::vector<Point2> outline_mm;     ///< simple polygon, either orientation
  double top_z_mm{0.0};
  double bottom_z_mm{-20.0};
  std::vector<PocketFeature> pockets;
  double cell_mm{0.025};
  /// Throws ConfigError naming `where`: < 3 outline points, top <= bottom,
  /// cell outside [0.005, 1] mm, a grid over 80 million cells, a bad pocket.
  void validate(const std::string& where) const;
  /// A rectangle [x0, x1] x [y0, y1].
  static std::vector<Point2> rectangle(double x0, double y0, double x1, double y1);
};

class HeightMapStock {
 public:
  explicit HeightMapStock(const StockSpec& spec);

  /// True when (x, y, z) (mm) lies inside remaining material.
  bool has_material(double x_mm, double y_mm, double z_mm) const noexcept {
    const std::size_t cell = cell_at(x_mm, y_mm);
    if (cell == kNoCell) return false;
    return z_mm > bottom_z_mm_ && z_mm < static_cast<double>(top_[cell]);
  }
  /// How many of the n points (cx + r s[i], cy + r c[i]) (mm) lie inside
  /// remaining material at height z_mm: has_material of each, counted.
  int count_in_material(double cx_mm, double cy_mm, double r_mm, const double* s, const double* c, std::size_t n,
                        double z_mm) const noexcept;
  /// Top of the material in the cell holding (x, y); bottom_z when none.
  double top_z_at_mm(double x_mm, double y_mm) const noexcept;

  /// Removes what `tool` sweeps moving straight from tip p0 to tip p1 (mm).
  /// With `whole` false, the caller guarantees that the sweep ending at p0 was
  /// removed before and did not move down (so the cells over the tool's flat
  /// core at p0 are at p0's height), and only the cells the move can still
  /// lower are visited: ahead of the line through p0 across the move.
  /// Returns the removed volume in mm^3.
  double remove_sweep(const ToolGeometry& tool, const std::array<double, 3>& p0_mm,
                      const std::array<double, 3>& p1_mm, bool whole);

  double cell_mm() const noexcept { return cell_mm_; }
  double top_z_mm() const noexcept { return top_z_mm_; }
  double bottom_z_mm() const noexcept { return bottom_z_mm_; }
  std::size_t nx() const noexcept { return nx_; }
  std::size_t ny() const noexcept { return ny_; }
  /// Volume of remaining material (mm^3), summed over cells.
  double volume_mm3() const;

 private:
  /// The index of the cell under (x, y) (mm) in the height map, or kNoCell
  /// off the map.
  static constexpr std::size_t kNoCell = static_cast<std::size_t>(-1);
  std::size_t cell_at(double x_mm, double y_mm) const noexcept {
    const double fx = (x_mm - x0_mm_) * inv_cell_;
    const double fy = (y_mm - y0_mm_) * inv_cell_;
    if (!(fx >= 0.0 && fy >= 0.0)) return kNoCell;
    const auto ix = static_cast<std::size_t>(fx);
    const auto iy = static_cast<std::size_t>(fy);
    if (ix >= nx_ || iy >= ny_) return kNoCell;
    return iy * nx_ + ix;
  }
  /// One straight move of the tool: the constants every visited cell needs.
  struct SweepCut {
    double R_mm, R2_mm2;             ///< tool radius and its square
    double Rc_mm;                    ///< radius of the flat core, R - r
    double r_mm, r2_mm2;             ///< corner radius and its square
    double p0x_mm, p0y_mm, p0z_mm;   ///< start of the move (tip)
    double Dx_mm, Dy_mm, Dz_mm;      ///< the move, p1 - p0
    double inv_L2_per_mm2;           ///< 1 / (Dx^2 + Dy^2), 0 for a move along z
    /// Cells whose top is at or below this height cannot be lowered by the
    /// move (the bottom, or the tip's lowest height less 1e-9 mm when that is
    /// higher: every cell is cut to the tip's height or above), so they are
    /// skipped before any arithmetic.
    double z_skip_mm;
  };
  SweepCut make_cut(const ToolGeometry& tool, const std::array<double, 3>& p0, const std::array<double, 3>& p1) const;
  void lower_cells_in_row(std::size_t iy, double xa, double xb, const SweepCut& cut, double& removed);
  /// The heights the cut leaves at the n cells ix, ix + 1, ... of the row at
  /// y (+inf beyond the tool's radius) into out[0, n rounded up to 4).
  void cut_heights(const SweepCut& cut, double y, std::size_t ix, std::size_t n, double* out) const;
  void cut_heights_avx(const SweepCut& cut, double y, std::size_t ix, std::size_t n, double* out) const;
  bool use_avx_{false};   ///< the CPU runs cut_heights_avx
  /// Cells per block of a row (64 bytes of heights).
  static constexpr std::size_t kBlock = 16;
  /// Recomputes the highest top of every block (after the stock is built).
  void refresh_block_max();
  double x0_mm_{0.0};
  double y0_mm_{0.0};
  double cell_mm_{0.025};
  double inv_cell_{40.0};
  std::size_t nx_{0};
  std::size_t ny_{0};
  double top_z_mm_{0.0};
  double bottom_z_mm_{0.0};
  std::vector<float> top_;
  /// Per row, per block of kBlock cells: an upper bound of the block's tops
  /// (exact after the block was last visited), so a sweep skips whole blocks
  /// it cannot lower (e.g. a pocket already at the bottom).
  std::size_t blocks_per_row_{0};
  std::vector<float> block_max_;
};

}  // namespace twin::process
