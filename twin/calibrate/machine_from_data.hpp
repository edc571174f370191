#pragma once
/// Calibration of a machine the twin does not know, from real logs
/// (spec/measured-data.md, "Position loops of real machines"): no FADAL prior.
///
/// 1. Data checks, each said in a note: stitched segments (a jump between two
///    rows larger than the axes move in a sample), the rounding of the logged
///    positions, dead or missing channels, the channel the torque is logged in
///    and its unit, the controller period.
/// 2. The loop: the cascade law of the spec, its position gain Kv (and kff)
///    from a logged velocity command where there is one, else from the lag of
///    the position behind the command; the velocity loop from a logged torque
///    against the velocity error where both speeds are logged, else chosen on
///    the fitting rows among 16 about a default well above the position loop,
///    and chosen again with smooth_friction (friction that creeps at rest),
///    the pair kept where it lowers the held-out error (said).
///    After the catalogue's effects, rising_friction (breakaway below the
///    Coulomb level: a stopped axis holds part of its sliding friction),
///    its share and speed chosen on the fitting rows, kept by the same rule.
/// 3. The drive in the channel's own unit (Kt = Ka = 1, rg = 1 mm/rad):
///    T = J a + B v + Tc_pos [v > 0] - Tc_neg [v < 0] + c, by least squares on
///    the commanded kinematics (the logged positions are often too coarse to
///    differentiate), c as a constant load.
/// 4. Replay of every segment from its own start, the twin's positions
///    rounded as the log rounds them; errors on the held-out rows against the
///    zero model and the rigid-body regression
///    T = m a_cmd + Fc sgn(v_cmd) + b v_cmd + c fitted on the same rows.
#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "twin/calibrate/effect_registry.hpp"
#include "twin/calibrate/signal.hpp"
#include "twin/report/replay.hpp"

namespace twin::analysis {

/// Rows [begin, end) of a run logged without a jump.
struct Segment {
  std::size_t begin{0}, end{0};
};

/// The stitched segments of a run: a row starts a new segment where any
/// axis's reference or position moves by more than the run shows its axes can
/// move in one sample (3 times the largest step held over three consecutive
/// samples on any axis, and at least 5 times the position quantum). With
/// `v_max_mm_per_s` (a known machine's rapid) the limit is that speed's step
/// with 20 % margin instead. On a log rounded coarser than 5 um and sampled
/// slower than 2 ms, a row where two or more axes step at once and the
/// path's step is over 3 quanta and 4 times the path's steps either side
/// starts a segment too. On such a log, where the jumps found recur every P
/// rows (a logger writing blocks of P rows and dropping some; at least half
/// the intervals P or P + 1), a row at least P - 1 rows from the jumps
/// either side starts a segment where an axis's speed changes for that row
/// alone by more than it does inside any block, plus 2 quanta of rounding.
/// A gap in the log's clock (run.time_breaks) starts a segment too. `note`
/// says what was found.
std::vector<Segment> find_segments(const MeasuredRun& run, double position_quantum_mm,
                                   std::optional<double> v_max_mm_per_s, std::string* note);

/// How a log rounds its positions.
struct PositionRounding {
  enum class Kind { kNone, kDecimals, kSignificant };
  Kind kind{Kind::kNone};
  int digits{0};                ///< decimals, or significant figures
  double quantum_mm{0.0};       ///< decimals: 10^-digits; significant: at the largest |position| of the run
  double round(double x_mm) const;
  std::string describe() const;
};
/// The coarsest rounding all logged positions (`<a>_ref_mm`, `<a>_mm`) agree with.
PositionRounding detect_rounding(const MeasuredRun& run);

/// A position logged with a rounding coarser than the motion between two
/// samples reads as a staircase: the reference stands still for several
/// samples and then steps by one quantum. The command itself moved smoothly,
/// crossing the rounding boundary between the last sample of one value and
/// the first of the next. This rebuilds it: knots at those crossings (the
/// mid-time, the mid-value) where consecutive values differ by about one
/// quantum, the samples themselves where they differ by more, flat where
/// the values turn back or the segment begins or ends (but for a slow move
/// that a stitch cut: carried on to the end at its speed), linear in between. A
/// single row off by more than a quantum between two equal neighbours is
/// taken as a logging glitch and given their value.
/// Applied to each segment on its own.
std::vector<double> dequantize_reference(const std::vector<double>& t_s, const std::vector<double>& r_mm,
                                         const PositionRounding& rounding);

/// The channel an axis's torque is logged in (first of <a>_torque_Nm,
/// <a>_torque_raw, <a>_i_A, <a>_u_V that is present), its unit and key for reports.
struct TorqueChannel {
  std::string column;  ///< empty: none
  std::string unit;    ///< "N m", "raw", "A", "V"
  bool present() const { return !column.empty(); }
};
TorqueChannel torque_channel(const MeasuredRun& run, Axis a);

/// Normalised RMS errors of a model on a set of rows, keyed as report.json
/// keys them (`x_i_A`, `x_err_mm`, ...). A key whose error could not be
/// computed is absent and its reason is in `not_computed`.
struct ChannelErrors {
  std::map<std::string, double> nrms;
  std::map<std::string, std::string> not_computed;
  nlohmann::json to_json() const;
};

/// What was found of one axis.
struct AxisFromData {
  Axis axis{Axis::kX};
  TorqueChannel channel;
  bool identified{false};
  std::string loop_source;       ///< how the loop's gains were found
  bool velocity_loop_from_data{false};  ///< Kvp, Tn from a logged torque against the speed error
  double lag_s{0.0};             ///< lag of the position behind the command
  controller::CascadeGains gains;
  /// The velocity law as read from the log, where it is then polished on
  /// the replay (a log slower than 5 ms): the polish fits it to the drive as
  /// identified, so it stands in for what that drive lacks.
  std::optional<controller::CascadeGains> law_before_polish;
  controller::CascadeGains default_velocity_loop;  ///< the gains before the velocity loop was chosen
  /// The velocity loop taken where the log does not show it (identify_velocity_loop's
  /// default), kept where the law read from a log slower than 5 ms must
  /// replay better than the best choice around it (choose_velocity_loops).
  controller::CascadeGains blind_velocity_loop;
  double J{0.0}, B{0.0}, Tc_pos{0.0}, Tc_neg{0.0}, c{0.0};  ///< channel unit, rg = 1 mm/rad
  double J_se{0.0}, B_se{0.0}, Tc_pos_se{0.0}, Tc_neg_se{0.0}, c_se{0.0};
  std::size_t fit_rows{0};
  /// The drive fitted with one Coulomb level for both directions (where the
  /// axis moves both ways): taken in place of the two levels where it lowers
  /// the held-out error by more than the keep margin (choose_coulomb_levels).
  struct OneLevel {
    bool ok{false};
    double J{0.0}, B{0.0}, Tc{0.0}, c{0.0};
    double J_se{0.0}, B_se{0.0}, Tc_se{0.0}, c_se{0.0};
    std::vector<std::string> clamped;  ///< physical floors applied, as for the two-level fit
  } one_level;
  bool one_coulomb_level{false};  ///< the one-level drive was taken
  std::string coulomb_choice;     ///< how the Coulomb levels were chosen, for the report
  /// Where the drive is fitted on the logged speed: the logged torque holds
  /// over the row it is logged at (a digital drive's sample and hold), so
  /// the acceleration it gives is the speed's forward difference over that
  /// row, not the central difference about it. Taken where the drive fitted
  /// so leaves the smaller residual beyond the rows' scatter
  /// (choose_torque_timing).
  bool torque_held_over_row{false};
  std::string torque_timing;  ///< how that was chosen, for the report
  /// Where the velocity loop is fitted from data: the lag (in samples of the
  /// log) at which the logged torque follows the PI law on the speed error
  /// best, and the gains fitted at that lag. A lag beyond 0 is a delay
  /// candidate (the gains above stay the lag-0 fit).
  std::size_t torque_lag_samples{0};
  /// Where the log is slower than the loop: the part of a row the lag runs
  /// beyond torque_lag_samples, in whole loop periods (0.5 for a 2 ms lag
  /// past the rows of a 4 ms log of a 1 ms loop); the law's columns are
  /// then taken between two rows, linearly.
  double torque_lag_fraction{0.0};
  /// The lag in rows of the log, whole and part.
  double torque_lag_rows() const { return static_cast<double>(torque_lag_samples) + torque_lag_fraction; }
  controller::CascadeGains gains_at_lag;
  /// The velocity loop's ticks per position-loop period the law's integral
  /// shows (1: one, at the position loop's tick); gains.Tv_s is the loop's
  /// period over it (choose_inner_ticks).
  int law_inner_ticks{1};
  /// With law_inner_ticks > 1: the logged torque at a row is the mean of the
  /// law's torques over the velocity loop's ticks of the period before it
  /// (a drive that averages what it traces), which fits the law better
  /// than the row's own tick (choose_inner_ticks); the machine replays the
  /// channel so (AxisDefinition::logged_torque_period_mean).
  bool law_period_mean{false};
  bool logs_period_mean() const { return law_period_mean && law_inner_ticks > 1; }
  /// The law fitted with the command's acceleration as a column too: the
  /// loop feeds a torque forward (gains.Jff_torque_s2_per_rad).
  bool torque_feedforward{false};
  /// Where the speed is the encoder's own (no motor speed logged): the
  /// period of a lead error the velocity law shows, fitted with the law
  /// from then on (0: none shown).
  double law_lead_period_mm{0.0};
  /// Where the speed is the encoder's own: a gap between the motor and the
  /// encoder the velocity law shows (0: none shown); the law is then fitted
  /// with its constants by the stretches of motion.
  double law_gap_mm{0.0};
  /// Where the logged torque stands at a limit after which the law resumes
  /// from a constant its running integral does not give: a limit that holds
  /// the velocity loop's integral while it clamps (anti-windup). The log's
  /// rows at the limit, per fitting run (empty: none shown); the law is then
  /// fitted without them and with a new constant after each stretch, and a
  /// limit found on the axis clamps the law's command (its T_max, which holds
  /// the integral alike) as well as the current.
  std::vector<std::vector<char>> law_limit_rows;
  double law_limit_level{0.0};  ///< the median |torque| the log holds at the limit
  /// Where the law's fit left out the rows a limit behind the loop holds:
  /// the |torque| the log flattens at (0: none). The law's polish replays
  /// with the motor's current clamped there.
  double law_clip_level{0.0};
  bool law_holds_integral_at_limit() const { return !law_limit_rows.empty(); }
  /// Where the law shows no lag of its own: the lag and dead time the drive
  /// fits the motion best at behind the logged torque (the drive's residual
  /// so, and at the torque's own rows), the candidate for a logged torque
  /// command (choose_torque_command).
  struct MotionBehindTorque {
    bool shown{false};
    std::size_t rows{0};
    double tau_s{0.0};
    double residual{0.0}, plain{0.0};
    double t{0.0};  ///< the fall from plain to residual in standard errors
    bool decisive{false};  ///< the fall is large enough to decide without a replay
  } motion_behind_torque;
  /// The log's torque is the loop's command, ahead of the motion by the
  /// current loop's lag (gains.tau_i_s) and the dead time
  /// (torque_lag_samples): the drive is fitted so and replayed giving it.
  bool torque_command_logged{false};
  std::string torque_command_choice;  ///< how that was chosen, for the report
  /// The lag the law shows between its output and the log (gains.tau_i_s)
  /// is a smoothed torque monitor's, outside the loop: the twin runs the
  /// loop without it and gives the logged channel through it
  /// (AxisDefinition::logged_torque_filter_s; place_law_lag).
  bool lag_in_monitor{false};
  /// With lag_in_monitor: the share of the lag (gains.tau_i_s) that is the
  /// current loop's, in the loop; the rest is the monitor's
  /// (split_monitor_lag; 0: all the monitor's).
  double lag_share_in_loop{0.0};
  /// Where the speed is taken from the position and no lag is read through
  /// its low-pass (a first-order lag fits there as a dead time of about the
  /// same total, or not beyond the law's noise): the law fitted with a
  /// first-order lag alone, its time constant in gains.tau_i_s, the
  /// candidate for a smoothed torque monitor (place_law_dead_time).
  std::optional<controller::CascadeGains> law_lag_alone;
  std::string note;
};

/// An effect tried on the identified model: kept only where it lowers the
/// held-out error of the axis's channel without raising the tracking error.
struct DataEffect {
  EffectKind kind{EffectKind::kStribeck};
  std::string effect;  ///< catalogue name of `kind`, as reports give it
  Axis axis{Axis::kX};
  std::map<std::string, double> params;
  std::string evidence;
  double before{0.0}, after{0.0};  ///< held-out channel NRMS without / with
  /// Held-out NRMS of every channel of the axis (torque, tracking error,
  /// velocity command) without and with the effect (empty for smooth_friction
  /// and rising_friction, whose before and after are the torque channel's).
  std::map<std::string, double> before_channels, after_channels;
  bool kept{false};

  void set_kind(EffectKind k) {
    kind = k;
    effect = std::string(feeddrive::effect_name(k));
  }
};

struct RunErrors {
  std::string run;
  ChannelErrors nominal;      ///< the machine the run names, or the stand-in when it names none
  ChannelErrors identified;   ///< identified, no effects
  ChannelErrors calibrated;   ///< final
  ChannelErrors zero;         ///< the zero model
  ChannelErrors regression;   ///< rigid-body regression (torque) and first-order lag (tracking), fitted on the fit runs
  /// Per torque channel: the twin's NRMS minus the regression's on the rows
  /// both are compared on, with its 90 % interval over 1 s blocks of them
  /// (paired_nrms_difference): whether a win or a loss is beyond the scatter
  /// of the rows. Absent where the rows are fewer than two blocks.
  std::map<std::string, PairedDifference> twin_minus_regression;
  /// Per torque channel of twin_minus_regression with a block where the twin
  /// loses: the log's times of that block's first and last rows, in s
  /// (PairedDifference::largest_loss_first_row), for a reader to look at.
  std::map<std::string, std::array<double, 2>> largest_loss_s;
  std::size_t rows{0}, rows_compared{0};
};

struct DataCalibration {
  sim::MachineDefinition identified;  ///< the cascade machine found, no effects
  sim::MachineDefinition final_machine;
  std::vector<Axis> axes;
  std::vector<AxisFromData> axis;
  PositionRounding rounding;
  /// The rounding is the log's (an export or display), not the encoder's:
  /// the identified machine closes its loop on a 1 um encoder and rounds its
  /// logged positions as the log's (choose_rounding says why).
  bool display_rounding{false};
  std::vector<DataEffect> effects;             ///< tried (kept or not)
  std::vector<std::pair<std::string, std::string>> skipped;  ///< effect, why the data cannot show it
  std::vector<RunErrors> fit_runs;             ///< held-out rows of each fitting run
  std::vector<RunErrors> validation_runs;      ///< whole runs not used for fitting
  /// The fitting runs' held-out rows and the validation runs' rows, each
  /// pooled over runs: sqrt(sum of squared residuals / sum of squared
  /// measurements) over all their compared rows.
  RunErrors pooled_fit, pooled_validation;
  ReplayResult replay_before, replay_after;    ///< of the first fitting run
  std::vector<std::string> notes;
  double fit_fraction{0.6};
  int replays{0};
};

struct DataCalibrationOptions {
  double fit_fraction{0.6};
  /// The loop period the twin replays at where no run gives it.
  double default_controller_period_s{1e-3};
};

/// Calibrates on `fit` (one or more runs of the same machine) and reports on
/// `validate`. `nominal` is the machine the runs are compared against before
/// calibration (the named one, or the stand-in with its note).
DataCalibration calibrate_from_data(const std::vector<MeasuredRun>& fit, const std::vector<MeasuredRun>& validate,
                                    const sim::MachineDefinition& nominal, const DataCalibrationOptions& options = {});

/// Replays `run` on `machine` segment by segment (each from its own start,
/// never across a jump), the twin's positions rounded as `rounding` says.
/// Rows of segments too short to replay keep the measured reference and are
/// flagged in `compared` = 0. Segments wholly outside `rows` are not
/// replayed either (their rows flagged 0 too): a segment's replay starts from
/// its own first row and never reads another's, so the rows in `rows` come
/// out as in the replay of every segment.
ReplayResult replay_segments(const MeasuredRun& run, const sim::MachineDefinition& machine,
                             const std::vector<Segment>& segments, const PositionRounding& rounding,
                             std::vector<char>* compared, Segment rows = {0, SIZE_MAX});

/// The errors of `machine` (identified by calibrate_from_data, in the log's
/// torque unit) on the whole of `run`, computed as calibrate's validation
/// computes them: segments, rounding and reference rebuilt from the run, the
/// replay kept in `replay`. Only `calibrated` and `zero` are filled.
RunErrors evaluate_machine_on_run(const MeasuredRun& run, const sim::MachineDefinition& machine, ReplayResult* replay,
                                  std::vector<std::string>* notes);

/// trace.csv of a replay on a machine identified from data: per axis the
/// reference, the twin's position (rounded as the log's), its torque in the
/// run's channel and unit, and the velocity command.
void write_data_trace(const std::filesystem::path& path, const MeasuredRun& run, const ReplayResult& replay);

nlohmann::json data_calibration_report_json(const DataCalibration& r);
std::string data_calibration_report_markdown(const DataCalibration& r, const std::string& runs);

}  // namespace twin::analysis
