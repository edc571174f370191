#pragma once
/// Replay of a measured run (spec/measured-data.md): the twin's loops follow
/// the run's `<a>_ref_mm` columns at the controller period and the twin's
/// trace is written with the same column names.
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "feeddrive/drive_bank.hpp"
#include "twin/io/trace_csv.hpp"
#include "twin/sim/machine.hpp"

namespace twin::analysis {

struct RunMeta {
  std::optional<std::string> machine;
  std::vector<Axis> axes;
  std::optional<double> controller_period_s;
  std::optional<double> sample_period_s;
  std::optional<double> encoder_resolution_mm;
  std::string description;
};

struct MeasuredRun {
  std::filesystem::path dir;
  RunMeta meta;
  io::TraceTable trace;
  std::vector<Axis> axes;          ///< axes with a <a>_ref_mm column
  double sample_period_s{0.0};     ///< from the time column (uniform within 1 %)
  /// Rows where t_s steps by more than 1.5 periods (rows missing, or the
  /// logger paused): each starts a part replayed from its own start.
  std::vector<std::size_t> time_breaks;
  std::vector<std::string> notes;  ///< what load_run left out of the trace, and why
  /// Channels load_run read whole rows earlier, logged after the motion
  /// they belong to (the logger's timing), and by how many rows.
  std::map<std::string, std::size_t> rows_read_earlier;
  /// A log that samples faster than its position loop runs: the rows of the
  /// log per loop period (1: the log is at the loop's period or slower).
  /// load_run keeps only the rows of the loop's ticks, so that the trace
  /// and sample_period_s are then the loop's.
  std::size_t log_rows_per_loop_period{1};
  /// The channel whose changes showed that period (empty where meta.json
  /// stated it), and the share of its changes on the loop's ticks.
  std::string loop_period_seen_in;
  double loop_period_share{0.0};
  /// Where load_run kept only the loop's ticks: the log's own rows, every
  /// column as read (the velocity command moved on as on the kept rows),
  /// their sample period, and the log's row each kept row is. A velocity
  /// loop that runs at the log's rate is fitted on these (its law holds on
  /// every row, and a speed differentiated there is not bent by the loop
  /// period's central difference); the replay runs on the kept rows.
  struct LogRows {
    io::TraceTable trace;
    double sample_period_s{0.0};
    std::vector<std::size_t> kept;
  };
  std::optional<LogRows> log_rows;
};

/// Reads RUN/meta.json and RUN/trace.csv(.gz); checks the columns and time.
/// A u or current column that holds one value over the whole run while its
/// axis moves (a channel that was not recorded) is left out, with a note.
/// t_s must be uniform within 1 %, or jitter by at most a fifth of a period
/// about a uniform grid (taken as on it, with a note), between gaps: a step of
/// over 1.5 periods is a gap (`time_breaks`, with a note), and a gap on more
/// than one row in 20 is an error. A torque or current column that lags the
/// axis's logged speed changes by a whole 1 to 3 rows (at 5 ms or faster) is
/// logged late: it is read that many rows earlier, with a note. A log
/// sampled faster than its position loop runs, by a whole 2 to 16 rows a
/// loop period (at most 10 ms), is cut to the rows of the loop's ticks,
/// with a note: where meta.json states the controller period so, or where
/// it states none and the loop's output (<a>_vcmd_mm_s or <a>_u_V) changes
/// on one row in every so many and held between (99 % of at least 100
/// changes); the rows it changes on are the loop's ticks. The log's own
/// rows are kept beside them (MeasuredRun::log_rows; dropped where a
/// channel is read rows earlier).
MeasuredRun load_run(const std::filesystem::path& dir);

/// The machine a run is replayed on: `machine_override` (name or path; one
/// that does not exist is a ConfigError) or the run's meta.machine, and where
/// that is null or not shipped, io::kDefaultMachineName with a note saying
/// what is assumed; the run's controller period and encoder resolution
/// replace the machine's where the meta gives them.
sim::MachineDefinition machine_for_run(const MeasuredRun& run, const std::string& machine_override,
                                       std::vector<std::string>* notes);

/// Whether the run's meta.json names a machine the twin ships (our own traces
/// do; a user's log from another machine does not, and is then handled as
/// data: stitches, rounding and a machine identified from it).
bool names_shipped_machine(const MeasuredRun& run);

struct ReplayResult {
  std::vector<Axis> axes;
  std::vector<double> t_s;                  ///< at the run's samples
  AxisArray<std::vector<double>> x_ref_mm;
  AxisArray<std::vector<double>> x_mm;      ///< measured (quantised) position of the twin
  AxisArray<std::vector<double>> u_V;
  /// Current and motor torque (the drive's torque unit), or the loop's
  /// command where the machine says the log holds that
  /// (AxisDefinition::torque_command_logged).
  AxisArray<std::vector<double>> i_A;
  AxisArray<std::vector<double>> Tm;
  AxisArray<std::vector<double>> vcmd_mm_per_s;  ///< cascade law: the velocity command (0 for FADAL)
  std::vector<std::string> notes;           ///< what was handled and how
};

/// The reference logged every m controller periods, rebuilt at every period
/// by a monotone piecewise cubic (Fritsch-Carlson): exact through constant
/// speed and constant acceleration, flat where the samples stop, and never
/// beyond the two samples around it. A straight line between samples would be
/// off by a dt^2 / 8 in an acceleration (25 um at 10 ms and 2000 mm/s^2),
/// ten times the tracking error of the FADAL loop.
///
/// `slopes`, where given, are the slopes to use at the samples (mm per sample
/// interval) in place of the monotone ones (reference_slopes).
std::vector<double> upsample_reference(const std::vector<double>& r_mm, std::int64_t m,
                                       const std::vector<double>* slopes = nullptr);

/// The slopes at the samples (mm per sample interval `dt_s`) of a rebuild
/// that passes through the reference's speed where the log shows it
/// (`v_mm_s`, NaN where it does not), and the monotone cubic's elsewhere.
/// A speed is taken where it goes the way of a neighbouring interval (or is
/// zero) and is at most three times the larger neighbouring secant; a speed
/// against both (a law identified wrong, or noise at a turn) keeps the
/// monotone slope.
std::vector<double> reference_slopes(const std::vector<double>& r_mm, const std::vector<double>& v_mm_s,
                                     double dt_s);

/// The logs a reference's speed is read off the law for: slower than this.
/// Faster, the monotone cubic is within 0.1 % of the tracking error's RMS
/// (a move's 500 mm/s^2 accelerations sampled every 5 ms).
inline constexpr double kLawSpeedMinPeriod_s = 5e-3;

/// The column that carries the reference's speed at each sample (mm/s),
/// where it is known: replay_run rebuilds the reference through it.
std::string reference_speed_column(Axis a);

/// Whether the run shows the reference's speed of axis `a` under the law of
/// `def` (law_reference_speed): it samples slower than
/// kLawSpeedMinPeriod_s, logs the axis's velocity command and position, and
/// the law is a cascade with a feedforward of at least 0.1 (1 / kff scales
/// the encoder's steps) following the reference as logged (no smoothing or
/// dead time before it).
bool shows_reference_speed(const MeasuredRun& run, Axis a, const sim::AxisDefinition& def);

/// The reference's speed at each sample as the cascade law of `def` shows
/// it in the run's logged velocity command, vcmd = Kv e + kff v_ref:
/// v_ref = (vcmd - Kv (ref - x)) / kff (mm/s); empty where the run does not
/// show it (shows_reference_speed). Between
/// samples 10 to 100 ms apart a move's change of speed takes part of an
/// interval, which the monotone cubic (zero slope where the samples stop)
/// spreads over it: at 50 ms that leaves 4 % of the tracking error's RMS in
/// the rebuilt reference, at 100 ms 21 %; through the speeds at the samples,
/// 1.4 % and 6.7 % (moves at 500 mm/s^2, docs/calibration.md).
std::vector<double> law_reference_speed(const MeasuredRun& run, Axis a, const sim::AxisDefinition& def);

/// The slopes at the samples (per sample interval) of that monotone cubic:
/// the centred difference, zero where the samples turn or stop, limited to
/// three times the smaller neighbouring secant.
std::vector<double> monotone_slopes(const std::vector<double>& r_mm);

/// Replays the run on `machine`. Where the samples are a whole multiple m of
/// the controller period, the reference is rebuilt by upsample_reference at the
/// controller period and outputs are taken every m ticks (a note says so);
/// any other sampling is a ConfigError naming the figures.
/// How the twin's torque-side channels (u, current, torque) are taken at a
/// row of a log that samples slower than the loop.
enum class ChannelSampling {
  /// The value at the row's tick.
  kInstant,
  /// The mean over the two sample periods around the row (every tick from
  /// t[k-1] to t[k+1]). A log sampled every dt fixes the reference only at its
  /// rows, so the rebuilt reference places a stop or a change of speed
  /// somewhere inside those two periods, not at a known tick; the value at one
  /// tick would put a short torque peak at a time the log cannot give. The
  /// mean is the expected value of the channel over the times the log allows.
  /// Equal to kInstant where the log samples every tick.
  kMeanOverNeighbours,
};

/// Rows [begin, end) of a run as a run of its own: the columns named, in the
/// run's order (every column where `names` is empty).
MeasuredRun rows_of(const MeasuredRun& run, std::size_t begin, std::size_t end,
                    const std::vector<std::string>& names = {});

/// `rows` limits the replay to the first rows (0: all).
ReplayResult replay_run(const MeasuredRun& run, const sim::MachineDefinition& machine, std::size_t rows = 0,
                        feeddrive::IntegratorOptions options = {},
                        ChannelSampling sampling = ChannelSampling::kInstant);

/// Writes the replay as trace.csv: t_s and per axis <a>_ref_mm <a>_mm <a>_u_V <a>_i_A.
void write_replay_trace(const std::filesystem::path& path, const ReplayResult& r);

}  // namespace twin::analysis
