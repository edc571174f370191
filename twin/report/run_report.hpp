#pragma once
/// Runs a scenario through the co-simulation loop, streams trace.csv and
/// builds summary.json: cycle time, per block the programmed and real feed,
/// tracking and contour errors, and per corner the real feed at its minimum,
/// the peak force and the time lost.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "controller/interpolator.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/io/trace_csv.hpp"
#include "twin/sim/cosimulation.hpp"

namespace twin::analysis {

/// Column names of a simulated trace for the given axes (spec columns first).
std::vector<std::string> run_trace_columns(const std::vector<Axis>& axes, bool tool_modes = false);
/// Fills one row in the order of run_trace_columns.
void fill_run_trace_row(const sim::Snapshot& s, const std::vector<Axis>& axes, std::vector<double>& row,
                        bool tool_modes = false);

/// Corner windows on the reference: where the reference speed dips below the
/// programmed feed around each corner.
struct CornerWindow {
  controller::Corner corner;
  int line_after{0};
  std::int64_t k_begin{0};
  std::int64_t k_end{0};        ///< exclusive
  double t_begin_s{0.0};
  double t_end_s{0.0};
  double feed_programmed_mm_per_min{0.0};
  double time_lost_s{0.0};      ///< integral of (1 - v_ref / F) over the window
  double feed_ref_min_mm_per_min{0.0};
};
std::vector<CornerWindow> corner_windows(const controller::Trajectory& trajectory,
                                         const controller::Program& program);

/// Accumulates per-tick statistics into the summary.
class RunStatistics {
 public:
  RunStatistics(const controller::Program& program, const controller::Trajectory& trajectory,
                std::vector<Axis> axes, double encoder_resolution_mm);
  void add(const sim::Snapshot& s);
  nlohmann::json summary() const;
  double cycle_time_s() const noexcept;
  const std::vector<CornerWindow>& corners() const noexcept { return windows_; }

 private:
  struct BlockStats {
    std::int64_t ticks{0};
    double feed_real_sum{0.0};
    double feed_real_min{1e300};
    AxisArray<double> max_err_mm{};
    double max_contour_mm{0.0};
    double peak_force_N{0.0};
  };
  struct CornerStats {
    double feed_real_min{1e300};
    double max_contour_mm{0.0};
    double peak_force_N{0.0};
    double max_engagement_deg{0.0};
    // Like for like (docs/interpolator.md, "Corner forces"): the straight cut
    // before the engagement ramp against the ramp through the corner.
    bool found{false};                    ///< a straight cut and a ramp were found
    bool zone_open{false};                ///< the ramp has not yet returned to the straight-cut engagement
    bool above_seen{false};               ///< the engagement has left the straight cut's band
    std::size_t tail_left{0};             ///< ticks of revolution means still counted after the ramp
    double engagement_straight_deg{0.0};
    double straight_t0_s{0.0}, straight_t1_s{0.0};
    double straight_mean_N{0.0};          ///< mean |F_avg| over whole revolutions before the ramp
    double straight_peak_N{0.0};
    double ramp_t0_s{0.0}, ramp_t1_s{0.0};
    double ramp_rev_mean_peak_N{0.0};     ///< largest one-revolution mean of |F_avg| in the ramp
    double ramp_peak_N{0.0};
  };
  /// One tick of the recent past, for the corner statistics.
  struct Recent {
    double t_s{0.0};
    double F_N{0.0};        ///< |F| instantaneous
    double F_avg_N{0.0};    ///< |F_avg| (tick average)
    double cum_F_avg_N{0.0};///< running sum of F_avg_N up to this tick
    double rev_mean_N{0.0}; ///< mean of F_avg_N over the revolution ending here
    double engagement_deg{0.0};
    double spindle_rpm{0.0};
  };
  void open_corner_zone(std::size_t c);
  /// Steps of add(): the run's errors, forces and times; the tick's block; the recent
  /// ticks and the engagement ramps at the corners; the corner windows holding the tick.
  void add_run(const sim::Snapshot& s, double F);
  void add_block(const sim::Snapshot& s, double F);
  void add_recent(const sim::Snapshot& s, double F);
  void update_ramps(const sim::Snapshot& s, const Recent& r, std::size_t n_rev);
  void add_corner_windows(const sim::Snapshot& s, double F);
  /// Parts of summary(): per block (adding each one's time at the programmed feed to
  /// `ideal_s`), per corner, and the forces.
  nlohmann::json blocks_json(double& ideal_s) const;
  nlohmann::json corner_json(std::size_t c) const;
  nlohmann::json forces_json() const;
  const controller::Program& program_;
  const controller::Trajectory& trajectory_;
  std::vector<Axis> axes_;
  double settle_band_mm_;
  std::vector<CornerWindow> windows_;
  std::vector<BlockStats> blocks_;
  std::vector<CornerStats> corner_stats_;
  std::size_t next_corner_{0};
  std::vector<Recent> recent_;     ///< ring buffer of the last kRecent_s of ticks
  std::size_t recent_head_{0};     ///< next slot to write
  std::size_t recent_count_{0};
  double cum_F_avg_N_{0.0};
  std::size_t next_zone_corner_{0};
  std::int64_t ticks_{0};
  double t_last_s_{0.0};
  double t_done_s_{-1.0};
  double t_settled_s_{-1.0};
  AxisArray<double> max_err_mm_{};
  AxisArray<double> sum_err2_{};
  double max_contour_mm_{0.0};
  double sum_contour2_{0.0};
  std::int64_t moving_ticks_{0};
  std::array<double, 3> peak_force_N_{};
  std::array<double, 3> sum_force_N_{};
  double peak_resultant_N_{0.0};
  std::int64_t cutting_ticks_{0};
  double energy_cut_J_{0.0};
  double Ts_s_{1e-4};
};

struct RunOutputs {
  nlohmann::json summary;
  std::filesystem::path trace_path;
  std::filesystem::path summary_path;
  std::vector<std::filesystem::path> plots;
};

struct RunOptions {
  std::filesystem::path out_dir;
  bool plots{true};
  /// Write every log_every-th tick to the trace (ticks 0, N, 2N, ...); the
  /// summary still takes in every tick. At least 1.
  std::int64_t log_every{1};
  /// trace.csv or trace.csv.gz.
  io::TraceFormat trace_format{io::TraceFormat::kCsv};
  /// Called every few thousand ticks with (ticks done, ticks in all); may be empty.
  std::function<void(std::int64_t, std::int64_t)> progress;
};

/// The whole `twin run`: plan, simulate, stream the trace, write the summary
/// and the plots. Files appear at their final names only when complete.
RunOutputs run_scenario(const io::Scenario& scenario, const RunOptions& options);

}  // namespace twin::analysis
