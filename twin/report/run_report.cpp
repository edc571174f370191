#include "twin/report/run_report.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include <fmt/format.h>

#include "process/chatter_spectrum.hpp"
#include "twin/report/plots.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/trace_csv.hpp"
#include "twin/sim/scenario.hpp"

namespace twin::analysis {

namespace {

/// A vibrating tool's figures over a run: the largest deflection and surface
/// location error, and the chatter verdict of the force spectrum
/// (process/chatter_spectrum.hpp) over consecutive windows of steady cutting
/// (engaged, the same spindle speed), L = max(0.1 s, 16 tooth periods).
class ToolStatistics {
 public:
  ToolStatistics(const process::ToolTipFrf& frf, int flutes, double Ts_s)
      : f_lo_(0.5 * frf.fn_min_Hz()), f_hi_(1.5 * frf.fn_max_Hz()), flutes_(flutes), Ts_(Ts_s) {}
  void add(const sim::Snapshot& s) {
    if (!s.tool_modes) return;
    max_deflection_um_ = std::max(max_deflection_um_, std::hypot(s.tool_deflection_um[0], s.tool_deflection_um[1]));
    max_sle_um_ = std::max(max_sle_um_, std::abs(s.sle_um));
    if (!(s.engagement_deg > 0.0 && s.spindle_rpm > 0.0) || s.spindle_rpm != rpm_) {
      F_.clear();
      r_prev_ = -1.0;
      rpm_ = s.spindle_rpm;
      if (!(s.engagement_deg > 0.0 && s.spindle_rpm > 0.0)) return;
    }
    F_.push_back({s.F_avg_N[0], s.F_avg_N[1]});
    const double tooth_Hz = rpm_ / 60.0 * flutes_;
    const auto window = static_cast<std::size_t>(std::ceil(std::max(0.1, 16.0 / tooth_Hz) / Ts_));
    if (F_.size() < window) return;
    const process::ChatterSpectrum sp = process::chatter_spectrum(F_, 0, window, Ts_, tooth_Hz, f_lo_, f_hi_);
    if (r_prev_ >= 0.0) {
      ++judged_;
      if (process::chatter_verdict(r_prev_, sp.ratio)) chatter_ = true;
      if (sp.ratio > max_ratio_) max_ratio_ = sp.ratio, chatter_Hz_ = sp.chatter_Hz;
    }
    r_prev_ = sp.ratio;
    F_.clear();
  }
  nlohmann::json summary() const {
    return {{"max_deflection_um", max_deflection_um_},
            {"max_abs_surface_location_error_um", max_sle_um_},
            {"chatter", judged_ > 0 ? nlohmann::json(chatter_ ? "chatter" : "stable") : nlohmann::json("not judged")},
            {"windows_judged", judged_},
            {"max_nonharmonic_ratio", max_ratio_},
            {"nonharmonic_Hz", chatter_Hz_}};
  }

 private:
  double f_lo_, f_hi_;
  int flutes_;
  double Ts_;
  double rpm_{0.0};
  std::vector<std::array<double, 2>> F_;
  double r_prev_{-1.0};
  double max_deflection_um_{0.0}, max_sle_um_{0.0}, max_ratio_{0.0}, chatter_Hz_{0.0};
  int judged_{0};
  bool chatter_{false};
};

/// The statistics of a vibrating tool, when the scenario's process has one.
std::optional<ToolStatistics> tool_statistics(const io::Scenario& sc) {
  if (!io::vibrating_tool(sc)) return std::nullopt;
  return ToolStatistics(sc.process_setup->tool_tip, sc.process_setup->tool.flutes, sc.machine.Ts_s);
}

/// The run's plots (gnuplot reads no gzip: a gzip trace is drawn from a plain
/// copy in the staging folder, which is not part of the result).
std::vector<std::filesystem::path> draw_run_plots(io::ResultSet& results, const RunOptions& options,
                                                  const std::string& trace_name, std::size_t rows,
                                                  const std::vector<Axis>& axes, const RunStatistics& stats,
                                                  bool cutting, const controller::Trajectory& traj) {
  if (options.trace_format == io::TraceFormat::kCsv)
    return plot_run(results, trace_name, rows, axes, stats.corners(), cutting, &traj);
  const auto plain = results.staging_dir() / "plot-trace.csv";
  io::gunzip_file(results.path(trace_name), plain);
  std::vector<std::filesystem::path> plots;
  try {
    plots = plot_run(results, plain.filename().string(), rows, axes, stats.corners(), cutting, &traj);
  } catch (const Error&) {
    std::error_code ec;
    std::filesystem::remove(plain, ec);
    throw;
  }
  std::error_code ec;
  std::filesystem::remove(plain, ec);
  return plots;
}

}  // namespace

std::vector<std::string> run_trace_columns(const std::vector<Axis>& axes, bool tool_modes) {
  std::vector<std::string> c{"t_s"};
  for (Axis a : axes) {
    const std::string n(axis_name(a));
    c.insert(c.end(), {n + "_ref_mm", n + "_mm", n + "_u_V", n + "_i_A"});
  }
  c.insert(c.end(), {"fx_N", "fy_N", "fz_N", "spindle_rpm"});
  for (Axis a : axes) {
    const std::string n(axis_name(a));
    c.insert(c.end(), {n + "_err_mm", n + "_true_mm", n + "_v_mm_per_s", n + "_Tm_Nm", n + "_Td_Nm"});
  }
  c.insert(c.end(), {"feed_programmed_mm_per_min", "feed_ref_mm_per_min", "feed_mm_per_min", "contour_error_mm",
                     "engagement_deg", "chip_mm", "spindle_torque_Nm", "cutting_power_W", "fx_avg_N", "fy_avg_N",
                     "fz_avg_N", "block"});
  // The cascade law's velocity command (spec/measured-data.md); 0 under the FADAL law.
  for (Axis a : axes) c.push_back(std::string(axis_name(a)) + "_vcmd_mm_s");
  // A vibrating tool: its deflection and the surface location error (process/milling_process.hpp).
  if (tool_modes) c.insert(c.end(), {"tool_dx_um", "tool_dy_um", "sle_um"});
  return c;
}

void fill_run_trace_row(const sim::Snapshot& s, const std::vector<Axis>& axes, std::vector<double>& row,
                        bool tool_modes) {
  row.clear();
  row.push_back(s.t_s);
  for (Axis a : axes) {
    const auto& x = s.axes[index(a)];
    row.insert(row.end(), {x.x_ref_mm, x.x_mm, x.u_V, x.i_A});
  }
  row.insert(row.end(), {s.F_N[0], s.F_N[1], s.F_N[2], s.spindle_rpm});
  for (Axis a : axes) {
    const auto& x = s.axes[index(a)];
    row.insert(row.end(), {x.e_mm, x.x_true_mm, x.v_mm_per_s, x.Tm_Nm, x.Td_Nm});
  }
  row.insert(row.end(), {s.feed_programmed_mm_per_min, s.feed_ref_mm_per_min, s.feed_real_mm_per_min,
                         s.contour_error_mm, s.engagement_deg, s.chip_mm, s.spindle_torque_Nm, s.cutting_power_W,
                         s.F_avg_N[0], s.F_avg_N[1], s.F_avg_N[2], static_cast<double>(s.block)});
  for (Axis a : axes) row.push_back(s.axes[index(a)].vcmd_mm_per_s);
  if (tool_modes) row.insert(row.end(), {s.tool_deflection_um[0], s.tool_deflection_um[1], s.sle_um});
}

std::vector<CornerWindow> corner_windows(const controller::Trajectory& traj, const controller::Program& program) {
  std::vector<CornerWindow> out;
  const double Ts = traj.Ts_s();
  const std::int64_t n = traj.num_ticks();
  const auto nb = static_cast<int>(program.blocks.size());
  auto cutting = [&](int b) {
    if (b < 0 || b >= nb) return false;
    const auto k = program.blocks[static_cast<std::size_t>(b)].kind;
    return k == controller::MotionKind::kLinear || k == controller::MotionKind::kArcCw ||
           k == controller::MotionKind::kArcCcw;
  };
  for (const auto& c : traj.corners()) {
    // Corners of the cut: both neighbours are feed moves (rapids stop anyway).
    if (!cutting(c.block_before) || !cutting(c.block_after)) continue;
    CornerWindow w;
    w.corner = c;
    w.line_after = program.blocks[static_cast<std::size_t>(c.block_after)].line;
    const double F_before = program.blocks[static_cast<std::size_t>(c.block_before)].feed_mm_per_min / kSPerMin;
    const double F_after = program.blocks[static_cast<std::size_t>(c.block_after)].feed_mm_per_min / kSPerMin;
    w.feed_programmed_mm_per_min = std::min(F_before, F_after) * kSPerMin;
    const auto kc = std::clamp<std::int64_t>(static_cast<std::int64_t>(std::llround(c.t_s / Ts)), 0, n);
    // The dip: from where the reference last ran at the feed of the block
    // before, to where it first runs at the feed of the block after.
    std::int64_t k0 = kc;
    double lost = 0.0;
    double vmin = traj.sample(kc).path_speed_mm_per_s;
    while (k0 > 0) {
      const auto s = traj.sample(k0 - 1);
      if (s.path_speed_mm_per_s >= 0.995 * F_before || (s.block != c.block_before && s.block != c.block_after)) break;
      lost += (1.0 - s.path_speed_mm_per_s / F_before) * Ts;
      vmin = std::min(vmin, s.path_speed_mm_per_s);
      --k0;
    }
    std::int64_t k1 = kc;
    while (k1 < n) {
      const auto s = traj.sample(k1);
      if (s.path_speed_mm_per_s >= 0.995 * F_after || (s.block != c.block_before && s.block != c.block_after)) break;
      lost += (1.0 - s.path_speed_mm_per_s / F_after) * Ts;
      vmin = std::min(vmin, s.path_speed_mm_per_s);
      ++k1;
    }
    // At least +-2 ms around the corner for the force and error statistics.
    const std::int64_t pad = static_cast<std::int64_t>(std::ceil(0.002 / Ts));
    w.k_begin = std::max<std::int64_t>(0, std::min(k0, kc - pad));
    w.k_end = std::min<std::int64_t>(n + 1, std::max(k1, kc + pad));
    w.t_begin_s = static_cast<double>(w.k_begin) * Ts;
    w.t_end_s = static_cast<double>(w.k_end) * Ts;
    w.time_lost_s = lost;
    w.feed_ref_min_mm_per_min = vmin * kSPerMin;
    out.push_back(w);
  }
  return out;
}

namespace {
/// How far back the corner statistics look (ring buffer of ticks).
constexpr double kRecent_s = 4.0;
/// Whole revolutions that make the straight-cut mean.
constexpr int kStraightRevolutions = 4;
/// Ticks in one spindle revolution (0 when the spindle stands).
std::size_t revolution_ticks(double rpm, double Ts_s) {
  if (!(std::abs(rpm) > 0.0)) return 0;
  return static_cast<std::size_t>(std::max(1.0, std::round(60.0 / std::abs(rpm) / Ts_s)));
}
/// Engagement still counted as the straight cut's: within max(2 deg, 5 %).
double engagement_band_deg(double straight_deg) { return straight_deg + std::max(2.0, 0.05 * straight_deg); }
}  // namespace

void RunStatistics::open_corner_zone(std::size_t c) {
  CornerStats& cs = corner_stats_[c];
  const std::size_t cap = recent_.size();
  const std::size_t n = recent_count_;
  if (n == 0) return;
  auto at = [&](std::size_t back) -> const Recent& { return recent_[(recent_head_ + cap - 1 - back) % cap]; };
  // The straight cut's engagement: the median over the older half of the
  // recent past, where the tool cut (a corner's ramp is far shorter).
  std::vector<double> older;
  for (std::size_t b = n / 2; b < n; ++b)
    if (at(b).engagement_deg > 0.0) older.push_back(at(b).engagement_deg);
  if (older.empty()) return;
  std::nth_element(older.begin(), older.begin() + static_cast<std::ptrdiff_t>(older.size() / 2), older.end());
  cs.engagement_straight_deg = older[older.size() / 2];
  const double band = engagement_band_deg(cs.engagement_straight_deg);
  // The ramp starts after the last tick before the corner whose engagement
  // is within the straight cut's band.
  std::size_t b = 0;
  while (b < n && at(b).engagement_deg > band) ++b;
  if (b >= n || at(b).engagement_deg <= 0.0) return;
  const std::size_t n_rev = revolution_ticks(at(b).spindle_rpm, Ts_s_);
  const std::size_t n_win = n_rev > 0 ? kStraightRevolutions * n_rev : static_cast<std::size_t>(std::llround(0.2 / Ts_s_));
  if (b + n_win > n) return;
  double sum = 0.0;
  for (std::size_t q = b; q < b + n_win; ++q) {
    if (at(q).engagement_deg <= 0.0) return;  // the straight cut must be a cut all along
    sum += at(q).F_avg_N;
    cs.straight_peak_N = std::max(cs.straight_peak_N, at(q).F_N);
  }
  cs.straight_mean_N = sum / static_cast<double>(n_win);
  cs.straight_t0_s = at(b + n_win - 1).t_s;
  cs.straight_t1_s = at(b).t_s;
  cs.ramp_t0_s = b > 0 ? at(b - 1).t_s : at(0).t_s;
  cs.ramp_t1_s = at(0).t_s;
  for (std::size_t q = 0; q < b; ++q) {
    cs.ramp_peak_N = std::max(cs.ramp_peak_N, at(q).F_N);
    cs.ramp_rev_mean_peak_N = std::max(cs.ramp_rev_mean_peak_N, at(q).rev_mean_N);
  }
  cs.found = true;
  cs.zone_open = true;
  cs.above_seen = b > 0;
}

RunStatistics::RunStatistics(const controller::Program& program, const controller::Trajectory& trajectory,
                             std::vector<Axis> axes, double encoder_resolution_mm)
    : program_(program),
      trajectory_(trajectory),
      axes_(std::move(axes)),
      settle_band_mm_(std::max(2.0 * encoder_resolution_mm, 1e-4)),
      windows_(corner_windows(trajectory, program)),
      blocks_(program.blocks.size()),
      corner_stats_(windows_.size()),
      Ts_s_(trajectory.Ts_s()) {
  if (!windows_.empty())
    recent_.resize(static_cast<std::size_t>(std::max<double>(1.0, std::ceil(kRecent_s / Ts_s_))));
}

void RunStatistics::add(const sim::Snapshot& s) {
  const double F = std::sqrt(s.F_N[0] * s.F_N[0] + s.F_N[1] * s.F_N[1] + s.F_N[2] * s.F_N[2]);
  add_run(s, F);
  add_block(s, F);
  // Recent ticks: |F|, |F_avg|, its one-revolution trailing mean, engagement
  // (kept only when the program has corners to judge).
  if (!recent_.empty()) add_recent(s, F);
  add_corner_windows(s, F);
}

void RunStatistics::add_run(const sim::Snapshot& s, double F) {
  ++ticks_;
  t_last_s_ = s.t_s;
  bool moving = !s.reference_done;
  bool settled = true;
  for (Axis a : axes_) {
    const auto& x = s.axes[index(a)];
    const double e = std::abs(x.e_mm);
    max_err_mm_[index(a)] = std::max(max_err_mm_[index(a)], e);
    if (moving) sum_err2_[index(a)] += e * e;
    if (std::abs(x.x_true_mm - x.x_ref_mm) > settle_band_mm_) settled = false;
  }
  if (moving) {
    ++moving_ticks_;
    sum_contour2_ += s.contour_error_mm * s.contour_error_mm;
  }
  max_contour_mm_ = std::max(max_contour_mm_, s.contour_error_mm);
  for (std::size_t c = 0; c < 3; ++c) {
    peak_force_N_[c] = std::max(peak_force_N_[c], std::abs(s.F_N[c]));
  }
  peak_resultant_N_ = std::max(peak_resultant_N_, F);
  if (s.engagement_deg > 0.0) {
    ++cutting_ticks_;
    for (std::size_t c = 0; c < 3; ++c) sum_force_N_[c] += s.F_avg_N[c];
  }
  energy_cut_J_ += s.cutting_power_W * Ts_s_;
  if (s.reference_done && t_done_s_ < 0.0) t_done_s_ = s.t_s;
  if (s.reference_done && settled && t_settled_s_ < 0.0) t_settled_s_ = s.t_s;
  if (!s.reference_done) t_settled_s_ = -1.0;
}

void RunStatistics::add_block(const sim::Snapshot& s, double F) {
  if (s.block < 0 || static_cast<std::size_t>(s.block) >= blocks_.size()) return;
  BlockStats& b = blocks_[static_cast<std::size_t>(s.block)];
  ++b.ticks;
  b.feed_real_sum += s.feed_real_mm_per_min;
  b.feed_real_min = std::min(b.feed_real_min, s.feed_real_mm_per_min);
  for (Axis a : axes_) b.max_err_mm[index(a)] = std::max(b.max_err_mm[index(a)], std::abs(s.axes[index(a)].e_mm));
  b.max_contour_mm = std::max(b.max_contour_mm, s.contour_error_mm);
  b.peak_force_N = std::max(b.peak_force_N, F);
}

void RunStatistics::add_recent(const sim::Snapshot& s, double F) {
  const double F_avg =
      std::sqrt(s.F_avg_N[0] * s.F_avg_N[0] + s.F_avg_N[1] * s.F_avg_N[1] + s.F_avg_N[2] * s.F_avg_N[2]);
  cum_F_avg_N_ += F_avg;
  Recent r;
  r.t_s = s.t_s;
  r.F_N = F;
  r.F_avg_N = F_avg;
  r.cum_F_avg_N = cum_F_avg_N_;
  r.engagement_deg = s.engagement_deg;
  r.spindle_rpm = s.spindle_rpm;
  const std::size_t cap = recent_.size();
  const std::size_t n_rev = revolution_ticks(s.spindle_rpm, Ts_s_);
  if (n_rev > 0 && n_rev <= recent_count_) {
    const Recent& first = recent_[(recent_head_ + cap - n_rev) % cap];
    r.rev_mean_N = (cum_F_avg_N_ - first.cum_F_avg_N) / static_cast<double>(n_rev);
  } else {
    r.rev_mean_N = F_avg;
  }
  recent_[recent_head_] = r;
  recent_head_ = (recent_head_ + 1) % cap;
  recent_count_ = std::min(recent_count_ + 1, cap);
  // Corners reached this tick: find the straight cut and the ramp in the past.
  while (next_zone_corner_ < windows_.size() &&
         static_cast<std::int64_t>(std::llround(windows_[next_zone_corner_].corner.t_s / Ts_s_)) <= s.k)
    open_corner_zone(next_zone_corner_++);
  update_ramps(s, r, n_rev);
}

void RunStatistics::update_ramps(const sim::Snapshot& s, const Recent& r, std::size_t n_rev) {
  // Open ramps: extend them until the engagement is back to the straight
  // cut's; the revolution means count one revolution longer (a revolution
  // ending there still holds the ramp).
  for (std::size_t c = 0; c < next_zone_corner_; ++c) {
    CornerStats& cs = corner_stats_[c];
    if (cs.tail_left > 0) {
      cs.ramp_rev_mean_peak_N = std::max(cs.ramp_rev_mean_peak_N, r.rev_mean_N);
      --cs.tail_left;
    }
    if (!cs.zone_open) continue;
    cs.ramp_t1_s = s.t_s;
    cs.ramp_peak_N = std::max(cs.ramp_peak_N, r.F_N);
    cs.ramp_rev_mean_peak_N = std::max(cs.ramp_rev_mean_peak_N, r.rev_mean_N);
    const bool in_band = r.engagement_deg <= engagement_band_deg(cs.engagement_straight_deg);
    cs.above_seen = cs.above_seen || !in_band;
    if ((in_band && cs.above_seen) || r.engagement_deg <= 0.0 || s.t_s - windows_[c].corner.t_s >= kRecent_s / 2.0) {
      cs.zone_open = false;
      cs.tail_left = r.engagement_deg > 0.0 ? n_rev : 0;
    }
  }
}

void RunStatistics::add_corner_windows(const sim::Snapshot& s, double F) {
  while (next_corner_ < windows_.size() && windows_[next_corner_].k_end <= s.k) ++next_corner_;
  for (std::size_t c = next_corner_; c < windows_.size() && windows_[c].k_begin <= s.k; ++c) {
    if (s.k >= windows_[c].k_end) continue;
    CornerStats& cs = corner_stats_[c];
    cs.feed_real_min = std::min(cs.feed_real_min, s.feed_real_mm_per_min);
    cs.max_contour_mm = std::max(cs.max_contour_mm, s.contour_error_mm);
    cs.peak_force_N = std::max(cs.peak_force_N, F);
    cs.max_engagement_deg = std::max(cs.max_engagement_deg, s.engagement_deg);
  }
}

double RunStatistics::cycle_time_s() const noexcept {
  if (t_settled_s_ >= 0.0) return t_settled_s_;
  return t_last_s_ + Ts_s_;
}

namespace {
std::string kind_name(controller::MotionKind k) {
  switch (k) {
    case controller::MotionKind::kRapid: return "G0";
    case controller::MotionKind::kLinear: return "G1";
    case controller::MotionKind::kArcCw: return "G2";
    case controller::MotionKind::kArcCcw: return "G3";
    case controller::MotionKind::kDwell: return "G4";
  }
  return "?";
}
}  // namespace

nlohmann::json RunStatistics::blocks_json(double& ideal_s) const {
  using nlohmann::json;
  const auto& bt = trajectory_.block_timings();
  json blocks = json::array();
  for (std::size_t i = 0; i < program_.blocks.size(); ++i) {
    const auto& b = program_.blocks[i];
    const BlockStats& s = blocks_[i];
    json jb;
    jb["index"] = i;
    jb["line"] = b.line;
    jb["motion"] = kind_name(b.kind);
    jb["feed_programmed_mm_per_min"] = b.kind == controller::MotionKind::kDwell ? 0.0 : b.feed_mm_per_min;
    if (i < bt.size()) {
      jb["length_mm"] = bt[i].length_mm;
      jb["time_s"] = bt[i].t_end_s - bt[i].t_start_s;
      const double at_feed = bt[i].feed_programmed_mm_per_s > 0.0 ? bt[i].length_mm / bt[i].feed_programmed_mm_per_s
                                                                  : bt[i].t_end_s - bt[i].t_start_s;
      jb["time_at_programmed_feed_s"] = at_feed;
      ideal_s += at_feed;
    }
    jb["feed_real_mean_mm_per_min"] = s.ticks > 0 ? s.feed_real_sum / static_cast<double>(s.ticks) : 0.0;
    jb["feed_real_min_mm_per_min"] = s.ticks > 0 ? s.feed_real_min : 0.0;
    json e = json::object();
    for (Axis a : axes_) e[std::string(axis_name(a))] = s.max_err_mm[index(a)];
    jb["max_tracking_error_mm"] = e;
    jb["max_contour_error_mm"] = s.max_contour_mm;
    jb["peak_force_N"] = s.peak_force_N;
    blocks.push_back(jb);
  }
  return blocks;
}

nlohmann::json RunStatistics::corner_json(std::size_t c) const {
  const auto& w = windows_[c];
  const auto& cs = corner_stats_[c];
  nlohmann::json jc;
  jc["index"] = c;
  jc["line"] = w.line_after;
  jc["turn_angle_deg"] = w.corner.turn_angle_deg;
  jc["p_mm"] = {w.corner.p_mm[0], w.corner.p_mm[1], w.corner.p_mm[2]};
  jc["t_s"] = w.corner.t_s;
  jc["exact_stop"] = w.corner.exact_stop;
  jc["feed_programmed_mm_per_min"] = w.feed_programmed_mm_per_min;
  jc["feed_ref_min_mm_per_min"] = w.feed_ref_min_mm_per_min;
  jc["feed_real_min_mm_per_min"] = cs.feed_real_min < 1e299 ? cs.feed_real_min : 0.0;
  jc["time_lost_s"] = w.time_lost_s;
  jc["max_contour_error_mm"] = cs.max_contour_mm;
  jc["peak_force_N"] = cs.peak_force_N;
  // Revolution means of |F_avg| and peaks of |F|: the straight cut before
  // the engagement ramp against the ramp through the corner (0 when no
  // straight cut of kStraightRevolutions whole revolutions precedes it).
  jc["mean_force_before_corner_N"] = cs.straight_mean_N;
  jc["window_s"] = {w.t_begin_s, w.t_end_s};
  jc["max_engagement_deg"] = cs.max_engagement_deg;
  jc["blend_radius_mm"] = w.corner.blend_radius_mm;
  jc["blend_deviation_mm"] = w.corner.deviation_mm;
  jc["feed_ref_at_corner_mm_per_min"] = w.corner.v_ref_mm_per_s * kSPerMin;
  jc["straight_cut_window_s"] = {cs.straight_t0_s, cs.straight_t1_s};
  jc["straight_cut_engagement_deg"] = cs.engagement_straight_deg;
  jc["straight_cut_peak_force_N"] = cs.straight_peak_N;
  jc["engagement_ramp_s"] = {cs.ramp_t0_s, cs.ramp_t1_s};
  jc["corner_revolution_mean_force_N"] = cs.ramp_rev_mean_peak_N;
  jc["corner_peak_force_N"] = cs.ramp_peak_N;
  jc["revolution_mean_force_ratio"] = cs.straight_mean_N > 0.0 ? cs.ramp_rev_mean_peak_N / cs.straight_mean_N : 0.0;
  jc["peak_force_ratio"] = cs.straight_peak_N > 0.0 ? cs.ramp_peak_N / cs.straight_peak_N : 0.0;
  return jc;
}

nlohmann::json RunStatistics::forces_json() const {
  nlohmann::json forces;
  forces["peak_N"] = {{"fx", peak_force_N_[0]}, {"fy", peak_force_N_[1]}, {"fz", peak_force_N_[2]}};
  const double ct = std::max<double>(1.0, static_cast<double>(cutting_ticks_));
  forces["mean_while_cutting_N"] = {
      {"fx", sum_force_N_[0] / ct}, {"fy", sum_force_N_[1] / ct}, {"fz", sum_force_N_[2] / ct}};
  forces["peak_resultant_N"] = peak_resultant_N_;
  forces["cutting_time_s"] = static_cast<double>(cutting_ticks_) * Ts_s_;
  forces["cutting_energy_J"] = energy_cut_J_;
  return forces;
}

nlohmann::json RunStatistics::summary() const {
  using nlohmann::json;
  json j;
  const double mt = std::max<double>(1.0, static_cast<double>(moving_ticks_));
  json max_err = json::object(), rms_err = json::object();
  for (Axis a : axes_) {
    max_err[std::string(axis_name(a))] = max_err_mm_[index(a)];
    rms_err[std::string(axis_name(a))] = std::sqrt(sum_err2_[index(a)] / mt);
  }
  double ideal = 0.0;
  const json blocks = blocks_json(ideal);
  json corners = json::array();
  double lost_total = 0.0;
  for (std::size_t c = 0; c < windows_.size(); ++c) {
    lost_total += windows_[c].time_lost_s;
    corners.push_back(corner_json(c));
  }
  j["ticks"] = ticks_;
  j["cycle_time_s"] = cycle_time_s();
  j["reference_time_s"] = trajectory_.duration_s();
  j["time_at_programmed_feed_s"] = ideal;
  j["time_lost_at_corners_s"] = lost_total;
  j["settled"] = t_settled_s_ >= 0.0;
  j["max_tracking_error_mm"] = max_err;
  j["rms_tracking_error_mm"] = rms_err;
  j["max_contour_error_mm"] = max_contour_mm_;
  j["rms_contour_error_mm"] = std::sqrt(sum_contour2_ / mt);
  j["forces"] = forces_json();
  j["blocks"] = blocks;
  j["corners"] = corners;
  return j;
}

RunOutputs run_scenario(const io::Scenario& scenario, const RunOptions& options) {
  const sim::PlannedProgram planned = sim::plan_program(scenario, scenario.machine);
  const controller::Program& program = planned.program;
  const controller::Trajectory& traj = planned.trajectory();
  sim::CoSimulation cosim = sim::build_cosimulation(scenario, {.reference = planned.reference});
  const auto& axes = cosim.axes();
  const std::int64_t total = sim::run_ticks(scenario, traj);

  // Every file is written in the result set's staging folder and appears in
  // OUT with the others, the manifest last (io::ResultSet).
  io::ResultSet results(options.out_dir, "run");
  RunOutputs out;
  if (options.log_every < 1)
    throw ConfigError(fmt::format("--log-every: {} is not a whole number of ticks >= 1", options.log_every));
  const std::string trace_name = io::trace_file_name(options.trace_format);
  std::optional<ToolStatistics> tool_stats = tool_statistics(scenario);
  const bool tool_modes = tool_stats.has_value();
  io::TraceWriter writer(results.path(trace_name), run_trace_columns(axes, tool_modes));
  RunStatistics stats(program, traj, axes, scenario.machine.encoder_resolution_mm);
  std::vector<double> row;
  for (std::int64_t k = 0, next_log = 0; k < total; ++k) {
    const sim::Snapshot& s = cosim.step();
    stats.add(s);
    if (tool_stats) tool_stats->add(s);
    if (k == next_log) {
      fill_run_trace_row(s, axes, row, tool_modes);
      writer.write_row(row);
      next_log += options.log_every;
    }
    if (options.progress && (k & 4095) == 0) options.progress(k, total);
  }
  nlohmann::json summary;
  summary["scenario"] = scenario.name;
  summary["machine"] = scenario.machine.name;
  summary["program"] = scenario.program_path.string();
  summary["process"] = sim::process_summary(scenario);
  summary["Ts_s"] = scenario.machine.Ts_s;
  const nlohmann::json st = stats.summary();
  summary.update(st);
  if (tool_stats) summary["tool"] = tool_stats->summary();
  summary["trace"] = {{"file", trace_name}, {"log_every_ticks", options.log_every}, {"rows", writer.num_rows()}};
  writer.commit();
  io::write_file_atomic(results.path("summary.json"), summary.dump(2) + "\n");
  out.summary = summary;
  std::vector<std::filesystem::path> plots;
  if (options.plots) {
    try {
      plots = draw_run_plots(results, options, trace_name, writer.num_rows(), axes, stats,
                             scenario.process_setup.has_value(), traj);
    } catch (const Error&) {
      results.commit();  // the trace and the summary stand without the plots
      throw;
    }
  }
  results.commit();
  out.trace_path = results.final_path(trace_name);
  out.summary_path = results.final_path("summary.json");
  for (const auto& p : plots) out.plots.push_back(results.final_path(p.filename().string()));
  return out;
}

}  // namespace twin::analysis
