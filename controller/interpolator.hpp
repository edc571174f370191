#pragma once
/// The CNC interpolator: turns a Program into the reference every axis
/// follows, sampled at the position-loop period Ts. Path feed with per-axis
/// velocity, acceleration and jerk limits (jerk-limited profiles), look-ahead
/// over the whole program, exact stop (G61.1), exact path (G61) and corners
/// rounded by blend arcs within a tolerance (G64 P). See controller/README.md
/// and docs/interpolator.md.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "controller/gcode.hpp"
#include "twin/core/axis.hpp"

namespace twin::controller {

struct MotionLimits {
  AxisArray<double> v_max_mm_per_s{};     ///< per-axis speed limit
  AxisArray<double> a_max_mm_per_s2{};    ///< per-axis acceleration limit
  AxisArray<double> j_max_mm_per_s3{};    ///< per-axis jerk limit
  double default_blend_tolerance_mm{0.01};///< G64 without P
  void validate() const;                  ///< ConfigError naming the field and value
};

/// The reference at one tick.
struct ReferenceSample {
  AxisArray<double> x_mm{};
  AxisArray<double> v_mm_per_s{};          ///< reference velocity (analytic)
  double path_speed_mm_per_s{0.0};         ///< |v| along the path
  double feed_programmed_mm_per_s{0.0};    ///< programmed feed of the current block (0 when idle)
  int block{-1};                           ///< index into Program::blocks; -1 before the first/after the last
  double spindle_rpm{0.0};
  bool cutting_move{false};                ///< G1/G2/G3 (not G0, not dwell)
  bool done{false};                        ///< motion finished
};

/// A corner of the programmed path: where the direction changes between two
/// consecutive motion blocks by more than a small angle.
struct Corner {
  int block_before{-1};
  int block_after{-1};
  double turn_angle_deg{0.0};       ///< change of direction (0: straight on)
  AxisArray<double> p_mm{};          ///< programmed corner point
  double t_s{0.0};                   ///< time the reference passes closest to it
  double v_ref_mm_per_s{0.0};        ///< reference path speed there
  bool exact_stop{false};
  double blend_radius_mm{0.0};       ///< radius of the blend arc (0: no blend)
  double deviation_mm{0.0};          ///< distance from p_mm to the planned path
  double t_blend_begin_s{0.0};       ///< the blend arc runs over [begin, end]
  double t_blend_end_s{0.0};         ///< (both t_s when there is no blend)
};

struct BlockTiming {
  double t_start_s{0.0};
  double t_end_s{0.0};
  double length_mm{0.0};
  double feed_programmed_mm_per_s{0.0};
};

/// One constant-jerk piece of a scalar time law s(t) along a move:
/// s = s0 + v0 tau + a0 tau^2/2 + j tau^3/6, tau = t - t0 in [0, duration].
struct LawPiece {
  double t0_s{0.0};
  double s0_mm{0.0};
  double v0_mm_per_s{0.0};
  double a0_mm_per_s2{0.0};
  double j_mm_per_s3{0.0};
};

/// The planned motion: a compact list of moves and their time laws
/// (memory grows with the number of blocks, not with the number of ticks).
///
/// Every move (a line, an arc or helix, a blend arc, or a dwell) carries its
/// own jerk-limited scalar law s(t) along its geometry; the moves follow one
/// another in time. A G64 corner is a blend arc tangent to both moves, split
/// in two halves that report the block before and the block after
/// (see docs/interpolator.md).
class Trajectory {
 public:
  Trajectory() = default;
  double Ts_s() const noexcept { return Ts_s_; }
  double duration_s() const noexcept;
  /// Ticks until the reference comes to rest at the program end.
  std::int64_t num_ticks() const noexcept;
  /// The reference at tick k (t = k Ts), for any k >= 0 (after the end it
  /// stays at the last point). O(log n) in the number of segments.
  ReferenceSample sample(std::int64_t k) const;
  /// The reference at a continuous time t_s >= 0 (sample(k) is at_time(k Ts)).
  ReferenceSample at_time(double t_s) const;
  const std::vector<Corner>& corners() const noexcept { return corners_; }
  const std::vector<BlockTiming>& block_timings() const noexcept { return block_timings_; }

  enum class SegmentKind { kLine, kArc, kBlend, kDwell };
  /// One move: geometry plus a time law [t_start_s, t_end_s].
  struct Segment {
    SegmentKind kind{SegmentKind::kLine};
    int block{-1};
    double t_start_s{0.0};
    double t_end_s{0.0};
    double length_mm{0.0};
    AxisArray<double> start_mm{};
    AxisArray<double> end_mm{};
    AxisArray<double> u{};            ///< line: unit direction
    double cx_mm{0.0}, cy_mm{0.0};    ///< arc: centre
    double r0_mm{0.0}, r1_mm{0.0};    ///< arc: start and end radius
    double phi0_rad{0.0}, dphi_rad{0.0};  ///< arc: start angle and signed sweep; blend: start angle and sweep > 0
    AxisArray<double> c_mm{};         ///< blend: centre; x = c + r0 (cos phi e1 + sin phi e2)
    AxisArray<double> e1{}, e2{};     ///< blend: orthonormal basis of its plane
    std::size_t first_piece{0};
    std::size_t num_pieces{0};
    double feed_mm_per_s{0.0};
    double spindle_rpm{0.0};
    bool cutting{false};
  };
  /// The planned moves in time order (blend arcs included).
  const std::vector<Segment>& segments() const noexcept { return segments_; }

 private:
  friend Trajectory plan_trajectory(const Program&, const MotionLimits&, double);
  /// Arc length s, speed and position of segment `seg` at time t_s.
  void eval_segment(const Segment& seg, double t_s, AxisArray<double>& x_mm,
                    AxisArray<double>& v_mm_per_s) const;

  double Ts_s_{1e-4};
  double duration_s_{0.0};
  AxisArray<double> start_mm_{};
  AxisArray<double> end_mm_{};
  double spindle_rpm_at_start_{0.0};
  double spindle_rpm_at_end_{0.0};
  std::vector<Corner> corners_;
  std::vector<BlockTiming> block_timings_;
  std::vector<Segment> segments_;
  std::vector<LawPiece> pieces_;
};

/// Refuses a program that cannot fit in the machine's travel. The twin has no
/// work offset (G54 is the identity), so program coordinates are work
/// coordinates: the program fits when, on every axis, the span of the
/// positions it reaches (its start, every end point, and the X and Y extremes
/// of its arcs) is at most travel_max - travel_min. ConfigError "file:line:
/// the move takes x to 700 mm: the program then spans [0, 700] mm in x, more
/// than the machine's travel of 559 mm ([0, 559])" at the first move that
/// breaks it.
void check_travel(const Program& program, const AxisArray<double>& travel_min_mm,
                  const AxisArray<double>& travel_max_mm);

/// Plans the program.
///  - line path limits: v <= min(F, min_a v_max,a/|u_a|), a_p = min_a a_max,a/|u_a|,
///    j_p likewise; arcs (programmed and blend): v^2 k <= (sqrt(3)/2) a,
///    tangential a/2, v^3 k (k + tau) <= j/3 (k curvature, tau torsion);
///  - S-curve speed changes dv: T = 2 Tj + Ta, Tj = min(a/j, sqrt(dv/j)), Ta = dv/a - a/j (>= 0);
///  - look-ahead over the whole program (backward and forward passes);
///  - G64 corners (line-line, line-arc, arc-line, arc-arc in XY): a blend arc
///    tangent to both moves, passing at most P from the corner point, taking
///    at most half of either move, of the smallest radius that lets the
///    slower neighbour's speed through (docs/interpolator.md);
///  - G61 (exact path) stops at corners, passes tangent junctions; G61.1
///    (exact stop) stops at the end of every block.
/// @throws ConfigError for limits or geometry that cannot be followed (an arc
///   whose end is not on its circle, a feed <= 0), a move whose length or
///   duration is not finite, or a plan longer than 2^53 ticks, naming file:line.
Trajectory plan_trajectory(const Program& program, const MotionLimits& limits, double Ts_s);

}  // namespace twin::controller
