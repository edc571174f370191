#include "twin/report/replay.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <string_view>

#include <Eigen/Dense>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "twin/core/error.hpp"
#include "twin/core/text.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::analysis {
namespace {

std::optional<double> optional_number(const nlohmann::json& j, const char* key, const std::string& where) {
  if (!j.contains(key) || j[key].is_null()) return std::nullopt;
  if (!j[key].is_number()) throw ConfigError(fmt::format("{}: {} must be a number or null", where, key));
  const double v = j[key].get<double>();
  if (!std::isfinite(v) || !(v > 0.0)) throw ConfigError(fmt::format("{}: {} = {} must be > 0", where, key, v));
  return v;
}

// meta.json of a run folder (spec/measured-data.md).
RunMeta read_meta(const std::filesystem::path& meta_path) {
  const std::string where = meta_path.string();
  RunMeta m;
  nlohmann::json meta;
  try {
    meta = nlohmann::json::parse(io::read_file(meta_path));
  } catch (const nlohmann::json::exception& e) {
    throw ConfigError(fmt::format("{}: not valid JSON ({})", where, e.what()));
  }
  if (!meta.is_object()) throw ConfigError(fmt::format("{}: must be a JSON object", where));
  if (meta.contains("machine") && !meta["machine"].is_null()) {
    if (!meta["machine"].is_string()) throw ConfigError(fmt::format("{}: machine must be a string or null", where));
    m.machine = meta["machine"].get<std::string>();
  }
  m.controller_period_s = optional_number(meta, "controller_period_s", where);
  m.sample_period_s = optional_number(meta, "sample_period_s", where);
  m.encoder_resolution_mm = optional_number(meta, "encoder_resolution_mm", where);
  if (meta.contains("description") && meta["description"].is_string())
    m.description = meta["description"].get<std::string>();
  if (meta.contains("axes")) {
    if (!meta["axes"].is_array()) throw ConfigError(fmt::format("{}: axes must be a list", where));
    for (const auto& a : meta["axes"]) {
      const auto ax = a.is_string() ? parse_axis(a.get<std::string>()) : std::nullopt;
      if (!ax) throw ConfigError(fmt::format("{}: axes: unknown axis {}", where, a.dump()));
      m.axes.push_back(*ax);
    }
  }
  return m;
}

// The trace's axes (those with a reference column), which must include meta.json's.
void find_axes(MeasuredRun& run) {
  for (Axis a : kAllAxes)
    if (run.trace.find(std::string(axis_name(a)) + "_ref_mm")) run.axes.push_back(a);
  if (run.axes.empty()) throw IoError(fmt::format("{}: no <a>_ref_mm column (x_ref_mm, y_ref_mm or z_ref_mm)", run.trace.source));
  for (Axis a : run.meta.axes)
    if (std::find(run.axes.begin(), run.axes.end(), a) == run.axes.end())
      throw IoError(fmt::format("{}: meta.json lists axis {} but the trace has no {}_ref_mm column", run.trace.source,
                                axis_name(a), axis_name(a)));
}

// A channel of an axis (its position, u, current, torque, velocity command
// or speed) constant over the whole run while the axis's command moves was
// not recorded: left out, and said.
void drop_unrecorded_channels(MeasuredRun& run) {
  for (Axis a : run.axes) {
    const std::string n(axis_name(a));
    const auto& ref = run.trace.at(n + "_ref_mm");
    const auto [rlo, rhi] = std::minmax_element(ref.begin(), ref.end());
    if (*rlo == *rhi) continue;  // a still axis may well hold u and current constant
    for (const std::string& col : {n + "_mm", n + "_u_V", n + "_i_A", n + "_torque_Nm", n + "_torque_raw",
                                   n + "_vcmd_mm_s", n + "_v_mm_s"}) {
      const auto it = std::find(run.trace.names.begin(), run.trace.names.end(), col);
      if (it == run.trace.names.end()) continue;
      const auto c = static_cast<std::size_t>(it - run.trace.names.begin());
      const auto& v = run.trace.columns[c];
      const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
      if (*lo != *hi) continue;
      run.notes.push_back(fmt::format("{}: {} holds {} over the whole run while axis {} moves: a channel that was not "
                                      "recorded; left out",
                                      run.trace.source, col, *lo, n));
      run.trace.names.erase(it);
      run.trace.columns.erase(run.trace.columns.begin() + static_cast<std::ptrdiff_t>(c));
    }
  }
}

/// A step of t_s longer than this many periods is a gap in the log.
constexpr double kGapPeriods = 1.5;
/// At most one gap in this many rows: more is not a log sampled at a period.
constexpr std::size_t kRowsPerGap = 20;

// The sample period of the trace's t_s, uniform within 1 % between gaps. A
// step of over 1.5 times the median step is a gap (rows missing, or the
// logger paused): recorded in run.time_breaks and said. A time stamp that
// jitters by up to a fifth of a period about the uniform grid of its part (a
// logger's clock, not the loop's) is taken as on the grid, and said.
double uniform_sample_period(MeasuredRun& run) {
  const auto& t = run.trace.at("t_s");
  const std::size_t n = t.size();
  if (n < 3) throw IoError(fmt::format("{}: {} rows are too few to replay", run.trace.source, n));
  std::vector<double> steps(n - 1);
  for (std::size_t r = 1; r < n; ++r) steps[r - 1] = t[r] - t[r - 1];
  std::vector<double> sorted = steps;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
  const double median = sorted[sorted.size() / 2];
  run.time_breaks.clear();
  double widest = 0.0;
  std::size_t widest_row = 0;
  for (std::size_t r = 1; r < n; ++r)
    if (steps[r - 1] > kGapPeriods * median) {
      run.time_breaks.push_back(r);
      if (steps[r - 1] > widest) {
        widest = steps[r - 1];
        widest_row = r;
      }
    }
  if (run.time_breaks.size() * kRowsPerGap > n)
    throw IoError(fmt::format("{}: sampling is not uniform: t_s steps by more than {} times its median step of {} s "
                              "on {} of {} rows (first at rows {} to {})",
                              run.trace.source, kGapPeriods, median, run.time_breaks.size(), n,
                              run.time_breaks.front() + 1, run.time_breaks.front() + 2));
  // The parts between gaps: the period is their mean step, and each part's
  // stamps lie on a grid of that period from the part's first row.
  std::vector<std::size_t> bounds{0};
  bounds.insert(bounds.end(), run.time_breaks.begin(), run.time_breaks.end());
  bounds.push_back(n);
  double span = 0.0;
  std::size_t counted = 0;
  for (std::size_t p = 0; p + 1 < bounds.size(); ++p) {
    span += t[bounds[p + 1] - 1] - t[bounds[p]];
    counted += bounds[p + 1] - 1 - bounds[p];
  }
  const double dt = counted > 0 ? span / static_cast<double>(counted) : median;
  double max_dev = 0.0;
  for (std::size_t p = 0; p + 1 < bounds.size(); ++p)
    for (std::size_t r = bounds[p]; r < bounds[p + 1]; ++r)
      max_dev = std::max(max_dev, std::abs(t[r] - t[bounds[p]] - static_cast<double>(r - bounds[p]) * dt));
  const double tol = max_dev <= 0.2 * dt ? 0.4 * dt : 0.01 * dt + 2e-6;
  for (std::size_t p = 0; p + 1 < bounds.size(); ++p)
    for (std::size_t r = bounds[p] + 1; r < bounds[p + 1]; ++r) {
      const double d = steps[r - 1];
      if (std::abs(d - dt) > tol)
        throw IoError(fmt::format("{}: sampling is not uniform: rows {} to {} are {} s apart, the mean period is {} s",
                                  run.trace.source, r + 1, r + 2, d, dt));
    }
  if (max_dev > 0.01 * dt + 2e-6)
    run.notes.push_back(fmt::format("{}: t_s jitters by up to {:.3g} s ({:.0f} % of the period) about a uniform grid: the "
                                    "rows are taken as sampled every {} s",
                                    run.trace.source, max_dev, 100.0 * max_dev / dt, dt));
  if (!run.time_breaks.empty())
    run.notes.push_back(fmt::format(
        "{}: t_s has {} gap{} (rows missing, or the log paused; the widest {:.4g} s, {:.3g} periods, before t = {:.6g} "
        "s): each of the {} parts is replayed from its own start, as a stitched segment",
        run.trace.source, run.time_breaks.size(), run.time_breaks.size() == 1 ? "" : "s", widest, widest / dt,
        t[widest_row], run.time_breaks.size() + 1));
  return dt;
}

/// The parts of a run between its time breaks, as [first row, end row).
std::vector<std::pair<std::size_t, std::size_t>> parts_between_breaks(const MeasuredRun& run, std::size_t n) {
  std::vector<std::pair<std::size_t, std::size_t>> parts;
  std::size_t from = 0;
  for (std::size_t b : run.time_breaks) {
    parts.emplace_back(from, b);
    from = b;
  }
  parts.emplace_back(from, n);
  return parts;
}

/// The lag in rows of a channel behind the signal it follows, from a least
/// squares fit of the channel on that signal at `taps` rows back (row k's
/// columns start with those taps, then any others): the centroid of the
/// taps' weights. nullopt where the fit fails or the weights do not sum
/// positive.
template <int kCols>
std::optional<double> centroid_lag(Eigen::Matrix<double, kCols, kCols> A, const Eigen::Matrix<double, kCols, 1>& b,
                                   std::size_t rows, int first_tap, int taps) {
  if (rows < 10 * static_cast<std::size_t>(kCols)) return std::nullopt;
  // A direction the axis never moves in leaves its column empty.
  for (Eigen::Index c = 0; c < kCols; ++c)
    if (A(c, c) == 0.0) A(c, c) = 1.0;
  const Eigen::Matrix<double, kCols, 1> w = A.ldlt().solve(b);
  double sum = 0.0, moment = 0.0;
  for (int j = 0; j < taps; ++j) {
    sum += w(j);
    moment += static_cast<double>(first_tap + j) * w(j);
  }
  if (!(std::isfinite(sum) && std::isfinite(moment) && sum > 0.0)) return std::nullopt;
  return moment / sum;
}

/// The speed's rows fitted on the position's central differences at -3 to 3
/// rows back.
constexpr int kSpeedTaps = 7;
/// The torque's rows fitted on the speed's forward differences at 0 to 4 rows
/// back, with the speed, a Coulomb level per direction and a constant.
constexpr int kTorqueTaps = 5;

/// The lag in rows of the logged speed `v` behind the logged position `x`.
/// Rows where the position steps faster than the speed ever goes (a stitch)
/// are left out.
std::optional<double> speed_lag_rows(const MeasuredRun& run, const std::vector<double>& x,
                                     const std::vector<double>& v) {
  const double dt = run.sample_period_s;
  double v_max = 0.0;
  for (double s : v) v_max = std::max(v_max, std::abs(s));
  Eigen::Matrix<double, kSpeedTaps, kSpeedTaps> A = Eigen::Matrix<double, kSpeedTaps, kSpeedTaps>::Zero();
  Eigen::Matrix<double, kSpeedTaps, 1> b = Eigen::Matrix<double, kSpeedTaps, 1>::Zero();
  std::size_t rows = 0;
  constexpr std::size_t reach = kSpeedTaps / 2 + 1;
  for (const auto& [first, end] : parts_between_breaks(run, v.size()))
    for (std::size_t k = first + reach; k + reach < end; ++k) {
      Eigen::Matrix<double, kSpeedTaps, 1> c;
      bool stitched = false;
      for (int j = 0; j < kSpeedTaps; ++j) {
        const std::size_t at = k + reach - 1 - static_cast<std::size_t>(j);  // tap -3 first
        c(j) = (x[at + 1] - x[at - 1]) / (2.0 * dt);
        stitched = stitched || std::abs(c(j)) > 2.0 * v_max + 1.0;
      }
      if (stitched) continue;
      A.noalias() += c * c.transpose();
      b.noalias() += c * v[k];
      ++rows;
    }
  return centroid_lag<kSpeedTaps>(A, b, rows, -(kSpeedTaps / 2), kSpeedTaps);
}

/// The lag in rows of a torque `T` behind the acceleration the logged speed
/// `v` shows.
std::optional<double> torque_lag_rows(const MeasuredRun& run, const std::vector<double>& v,
                                      const std::vector<double>& T) {
  const double dt = run.sample_period_s;
  double v_max = 0.0;
  for (double s : v) v_max = std::max(v_max, std::abs(s));
  const double v_moving = 0.01 * v_max;
  constexpr int kCols = kTorqueTaps + 4;
  Eigen::Matrix<double, kCols, kCols> A = Eigen::Matrix<double, kCols, kCols>::Zero();
  Eigen::Matrix<double, kCols, 1> b = Eigen::Matrix<double, kCols, 1>::Zero();
  std::size_t rows = 0;
  for (const auto& [first, end] : parts_between_breaks(run, v.size()))
    for (std::size_t k = first + kTorqueTaps - 1; k + 1 < end; ++k) {
      Eigen::Matrix<double, kCols, 1> x;
      for (int j = 0; j < kTorqueTaps; ++j) {
        const std::size_t at = k - static_cast<std::size_t>(j);
        x(j) = (v[at + 1] - v[at]) / dt;
      }
      x(kTorqueTaps) = v[k];
      x(kTorqueTaps + 1) = v[k] > v_moving ? 1.0 : 0.0;
      x(kTorqueTaps + 2) = v[k] < -v_moving ? 1.0 : 0.0;
      x(kTorqueTaps + 3) = 1.0;
      A.noalias() += x * x.transpose();
      b.noalias() += x * T[k];
      ++rows;
    }
  return centroid_lag<kCols>(A, b, rows, 0, kTorqueTaps);
}

/// A lag within 0.3 rows of a whole 1 to 3 rows: that many rows; else 0.
std::size_t whole_rows_late(const std::optional<double>& lag) {
  if (!lag) return 0;
  const long rows = std::lround(*lag);
  if (rows < 1 || rows > 3 || std::abs(*lag - static_cast<double>(rows)) > 0.3) return 0;
  return static_cast<std::size_t>(rows);
}

/// The column read `s` rows earlier within each part between time breaks,
/// the last rows of each part holding its last logged value.
void read_rows_earlier(const MeasuredRun& run, std::vector<double>& c, std::size_t s) {
  for (const auto& [first, end] : parts_between_breaks(run, c.size()))
    for (std::size_t k = first; k < end; ++k) c[k] = c[std::min(k + s, end - 1)];
}

// Channels logged whole rows after the motion they belong to (a logger that
// samples some of the drive's signals a cycle late, or several loggers).
// Checked in a chain from the position, whose rows are the loop's: the
// speed against the position's changes (a kinematic identity), then each
// torque or current against the speed's changes (the drive's dynamics). A
// delay in the drive (its current loop, a dead time) delays the torque and
// the speed's change together, so only the log's own timing puts a torque
// behind that change. A channel lagging by 1 to 3 whole rows is read that
// many rows earlier, with a note. Only lags, not leads: backlash and a
// compliant drive put the motor's speed ahead of the table's position, and a
// delay after the logged current puts it ahead of the motion. Checked where
// the axis's speed is logged at 5 ms or faster.
void realign_late_channels(MeasuredRun& run) {
  if (!(run.sample_period_s <= 5e-3 + 1e-12)) return;
  const auto column = [&](const std::string& name) -> std::vector<double>* {
    const auto it = std::find(run.trace.names.begin(), run.trace.names.end(), name);
    return it == run.trace.names.end() ? nullptr
                                       : &run.trace.columns[static_cast<std::size_t>(it - run.trace.names.begin())];
  };
  const auto say = [&](const std::string& col, std::size_t rows, double lag, const char* behind, const char* why) {
    run.rows_read_earlier[col] = rows;
    run.notes.push_back(fmt::format("{}: {} is logged {} row{} after the motion it belongs to: it lags {} by {:.2f} "
                                    "rows{}; read {} row{} earlier, the logger's timing, not the machine's",
                                    run.trace.source, col, rows, rows == 1 ? "" : "s", behind, lag, why, rows,
                                    rows == 1 ? "" : "s"));
  };
  for (Axis a : run.axes) {
    const std::string n(axis_name(a));
    std::vector<double>* v = column(n + "_v_mm_s");
    if (v == nullptr) continue;
    if (const std::vector<double>* x = column(n + "_mm")) {
      const std::optional<double> lag = speed_lag_rows(run, *x, *v);
      if (const std::size_t s = whole_rows_late(lag)) {
        read_rows_earlier(run, *v, s);
        say(n + "_v_mm_s", s, *lag, "the position's changes", "");
      }
    }
    for (const std::string& col : {n + "_torque_raw", n + "_torque_Nm", n + "_i_A"}) {
      std::vector<double>* T = column(col);
      if (T == nullptr) continue;
      const std::optional<double> lag = torque_lag_rows(run, *v, *T);
      if (const std::size_t s = whole_rows_late(lag)) {
        read_rows_earlier(run, *T, s);
        say(col, s, *lag, "the speed's changes", " (a delay in the drive would delay both)");
      }
    }
  }
}

/// A loop slower than its log: at most this period, and this many rows a period.
constexpr double kMaxHeldLoopPeriod_s = 0.01;
constexpr std::size_t kMaxRowsPerLoopPeriod = 16;
/// The least number of changes of the loop's output a period is read from,
/// and the share of them that must fall on the loop's ticks.
constexpr std::size_t kMinOutputChanges = 100;
constexpr double kHeldShare = 0.99;

/// The loop's ticks among the rows of a log faster than the loop.
struct LoopTicks {
  std::size_t every{1};  ///< rows per loop period
  /// Per part of the run between gaps in its clock (parts_between_breaks):
  /// the first row of a tick, counted from the part's first row.
  std::vector<std::size_t> phase;
  std::string channel;  ///< the loop output that showed them
  double share{0.0};    ///< of the rows it changes on, the part on the ticks
  std::size_t changes{0};
};

/// The rows a position loop's output (every axis's `<a>_vcmd_mm_s`, else
/// `<a>_u_V`) changes on, as a loop slower than the log holds it between
/// its ticks: the most rows per period `every` (2 to 16, the period at most
/// 10 ms) for which one phase in each part of the run between gaps in its
/// clock (the logger's clock restarts there) holds, over the parts, 99 % of
/// at least 100 changes. A loop at the log's period changes it on any row
/// (its following error moves with the encoder's counts), so no phase holds
/// most; every = 1 where none is found. `parts`: the run's parts between
/// gaps in its clock (parts_between_breaks).
LoopTicks held_loop_output(const MeasuredRun& run, const std::vector<std::pair<std::size_t, std::size_t>>& parts) {
  LoopTicks none;
  const std::size_t n = run.trace.num_rows();
  const double dt = run.sample_period_s;
  if (!(dt > 0.0)) return none;
  const auto most = std::min<std::size_t>(
      kMaxRowsPerLoopPeriod, static_cast<std::size_t>(std::floor(kMaxHeldLoopPeriod_s / dt + 1e-9)));
  if (most < 2) return none;
  std::vector<char> changes(n, 0);  // rows on which an axis's output changed
  std::string channel;
  for (const char* suffix : {"_vcmd_mm_s", "_u_V"}) {
    for (Axis a : run.axes) {
      const std::string name = std::string(axis_name(a)) + suffix;
      const std::vector<double>* c = run.trace.find(name);
      if (c == nullptr) continue;
      if (channel.empty()) channel = name;
      for (std::size_t k = 1; k < n; ++k)
        if ((*c)[k] != (*c)[k - 1]) changes[k] = 1;
    }
    if (!channel.empty()) break;
  }
  std::size_t total = 0;
  for (const auto& [first, end] : parts)
    for (std::size_t k = first + 1; k < end; ++k) total += changes[k] != 0;
  if (total < kMinOutputChanges) return none;
  std::vector<std::size_t> on(most);
  for (std::size_t every = most; every >= 2; --every) {
    LoopTicks t{every, {}, channel, 0.0, total};
    std::size_t held = 0;
    for (const auto& [first, end] : parts) {
      std::fill(on.begin(), on.end(), 0);
      for (std::size_t k = first + 1; k < end; ++k)
        if (changes[k]) ++on[(k - first) % every];
      const auto best = std::max_element(on.begin(), on.begin() + static_cast<std::ptrdiff_t>(every));
      held += *best;
      t.phase.push_back(static_cast<std::size_t>(best - on.begin()));
    }
    t.share = static_cast<double>(held) / static_cast<double>(total);
    if (t.share >= kHeldShare) return t;
  }
  return none;
}

/// How many rows after the loop's tick its velocity command shows a new
/// value (0 to every - 1): a logger that samples the command before the loop
/// updates it at a tick shows the new value a row later. The P law
/// vcmd = Kv e + kff v_ref + c is fitted by least squares on the rows the
/// command changes on, with the following error and the reference's speed
/// over a loop period taken s rows earlier; s is the one of the smallest
/// residual, where that is under half the residual at s = 0 (the law holds
/// exactly at its own tick, but for the log's rounding). `residuals`
/// receives the residual RMS at each s; `parts` as held_loop_output's.
std::size_t vcmd_rows_after_tick(const MeasuredRun& run, const std::vector<std::pair<std::size_t, std::size_t>>& parts,
                                 const LoopTicks& t, std::vector<double>& residuals) {
  residuals.clear();
  constexpr std::string_view kVcmd = "_vcmd_mm_s";
  if (!t.channel.ends_with(kVcmd)) return 0;
  const std::string axis = t.channel.substr(0, t.channel.size() - kVcmd.size());
  const std::vector<double>*ref = run.trace.find(axis + "_ref_mm"), *x = run.trace.find(axis + "_mm"),
        *v = run.trace.find(t.channel);
  if (ref == nullptr || x == nullptr || v == nullptr) return 0;
  const std::size_t m = t.every;
  const double period = static_cast<double>(m) * run.sample_period_s;
  for (std::size_t late = 0; late < m; ++late) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    double yy = 0.0;
    std::size_t rows = 0;
    for (std::size_t p = 0; p < parts.size(); ++p)
      for (std::size_t k = parts[p].first + t.phase[p] + 2 * m; k < parts[p].second; k += m) {
        const std::size_t at = k - late;
        const Eigen::Vector3d c((*ref)[at] - (*x)[at], ((*ref)[at] - (*ref)[at - m]) / period, 1.0);
        A.noalias() += c * c.transpose();
        b.noalias() += c * (*v)[k];
        yy += (*v)[k] * (*v)[k];
        ++rows;
      }
    if (rows < kMinOutputChanges) return 0;
    const Eigen::Vector3d theta = A.ldlt().solve(b);
    const double sse = std::max(0.0, yy - theta.dot(b));
    if (!std::isfinite(sse)) return 0;
    residuals.push_back(std::sqrt(sse / static_cast<double>(rows)));
  }
  const auto best = static_cast<std::size_t>(std::min_element(residuals.begin(), residuals.end()) - residuals.begin());
  return best > 0 && residuals[best] < 0.5 * residuals[0] ? best : 0;
}

/// Where the log samples faster than the position loop runs (meta.json's
/// controller period a whole number of sample periods, or none stated and
/// the loop's output held between its ticks): the rows of the loop's ticks
/// kept in each part of the run between gaps in its clock, the others left
/// out, and said.
void keep_loop_ticks(MeasuredRun& run) {
  const double dt = run.sample_period_s;
  const std::size_t n = run.trace.num_rows();
  const auto parts = parts_between_breaks(run, n);
  LoopTicks ticks;
  if (run.meta.controller_period_s) {
    const double ratio = *run.meta.controller_period_s / dt;
    const auto every = static_cast<std::size_t>(std::llround(ratio));
    if (ratio < 1.5 || every > kMaxRowsPerLoopPeriod || std::abs(ratio - static_cast<double>(every)) > 0.01) return;
    const LoopTicks seen = held_loop_output(run, parts);
    ticks = seen.every == every ? seen : LoopTicks{every, std::vector<std::size_t>(parts.size(), 0), "", 0.0, 0};
  } else {
    ticks = held_loop_output(run, parts);
    if (ticks.every < 2) return;
  }
  // The loop's ticks: the rows the command changes on, or `late` rows
  // before them where it shows each value late; every axis's velocity
  // command is then read that many rows on.
  std::vector<double> residuals;
  const std::size_t late = vcmd_rows_after_tick(run, parts, ticks, residuals);
  const std::size_t m = ticks.every;
  std::vector<std::size_t> rows;  // the rows kept, and where each part's start among them
  std::vector<std::size_t> breaks;
  for (std::size_t p = 0; p < parts.size(); ++p) {
    const auto [first, end] = parts[p];
    const std::size_t before = rows.size();
    const std::size_t from = first + (late > 0 ? ticks.phase[p] + m - late : ticks.phase[p]);
    for (std::size_t k = from; k + late < end; k += m) rows.push_back(k);
    if (before > 0 && rows.size() > before) breaks.push_back(before);  // a part with no tick leaves no part
  }
  if (rows.size() < 3)
    throw IoError(fmt::format("{}: {} rows are too few to replay at the position loop's period of {} sample periods",
                              run.trace.source, n, m));
  MeasuredRun::LogRows log{run.trace, dt, rows};
  for (std::size_t c = 0; c < log.trace.columns.size(); ++c) {
    if (late == 0 || !log.trace.names[c].ends_with("_vcmd_mm_s")) continue;
    auto& col = log.trace.columns[c];
    for (const auto& [first, end] : parts)
      for (std::size_t k = first; k < end; ++k) col[k] = k + late < end ? col[k + late] : col[end - 1];
  }
  run.log_rows = std::move(log);
  for (std::size_t c = 0; c < run.trace.columns.size(); ++c) {
    auto& col = run.trace.columns[c];
    const std::size_t shift = run.trace.names[c].ends_with("_vcmd_mm_s") ? late : 0;
    for (std::size_t j = 0; j < rows.size(); ++j) col[j] = col[rows[j] + shift];
    col.resize(rows.size());
  }
  run.time_breaks = breaks;
  run.sample_period_s = dt * static_cast<double>(m);
  if (run.meta.sample_period_s) run.meta.sample_period_s = run.sample_period_s;
  run.log_rows_per_loop_period = m;
  run.loop_period_seen_in = ticks.channel;
  run.loop_period_share = ticks.share;
  const std::string why =
      !ticks.channel.empty()
          ? fmt::format("{} changes only on every {} row ({:.1f} % of the {} rows the loop's output changes on)",
                        ticks.channel, ordinal(m), 100.0 * ticks.share, ticks.changes)
          : std::string("meta.json's controller period (the loop's output does not show on which rows it ticks: "
                        "the first row taken as a tick)");
  std::string from_rows = fmt::format("row {}", rows.front() + 1);
  for (std::size_t b : breaks) from_rows += fmt::format(", after the gap from row {}", rows[b] + 1);
  run.notes.push_back(fmt::format("{}: the log samples every {} s, {} times a position-loop period ({}): the {} rows "
                                  "of the loop's ticks are kept (every {} from {}), the rows between left out",
                                  run.trace.source, dt, m, why, rows.size(), ordinal(m), from_rows));
  if (late > 0)
    run.notes.push_back(fmt::format(
        "{}: {} shows each new value {} row{} after the loop's tick (the logger samples it before the loop updates "
        "it): its P law fits the position {} row{} earlier with a residual of {:.3g} mm/s against {:.3g} at the "
        "row itself; the velocity command is read {} row{} on, the logger's timing, not the machine's",
        run.trace.source, ticks.channel, late, late == 1 ? "" : "s", late, late == 1 ? "" : "s", residuals[late],
        residuals[0], late, late == 1 ? "" : "s"));
}

}  // namespace

MeasuredRun load_run(const std::filesystem::path& dir) {
  MeasuredRun run;
  run.dir = dir;
  if (!std::filesystem::is_directory(dir)) throw IoError(fmt::format("{}: not a run folder", dir.string()));
  const auto meta_path = dir / "meta.json";
  run.meta = read_meta(meta_path);
  std::filesystem::path trace_path = dir / "trace.csv";
  if (!std::filesystem::exists(trace_path)) trace_path = dir / "trace.csv.gz";
  if (!std::filesystem::exists(trace_path))
    throw IoError(fmt::format("{}: no trace.csv or trace.csv.gz", dir.string()));
  run.trace = io::read_trace_csv(trace_path);
  find_axes(run);
  drop_unrecorded_channels(run);
  const double dt = uniform_sample_period(run);
  run.sample_period_s = dt;
  if (run.meta.sample_period_s && std::abs(*run.meta.sample_period_s - dt) > 0.01 * dt)
    throw IoError(fmt::format("{}: sample_period_s = {} s but the trace's t_s steps by {} s", meta_path.string(),
                              *run.meta.sample_period_s, dt));
  keep_loop_ticks(run);
  realign_late_channels(run);
  if (!run.rows_read_earlier.empty()) run.log_rows.reset();  // the log's rows are as logged, not realigned
  return run;
}

bool names_shipped_machine(const MeasuredRun& run) {
  return run.meta.machine && !run.meta.machine->empty() &&
         std::filesystem::exists(io::resolve_machine_path(*run.meta.machine));
}

sim::MachineDefinition machine_for_run(const MeasuredRun& run, const std::string& machine_override,
                                       std::vector<std::string>* notes) {
  std::string name = machine_override.empty() ? run.meta.machine.value_or("") : machine_override;
  auto path = io::resolve_machine_path(name);
  if (name.empty() || !std::filesystem::exists(path)) {
    if (!machine_override.empty())
      throw ConfigError(fmt::format("--machine {}: no such machine file ({} does not exist)", machine_override,
                                    path.string()));
    // A run from a machine the twin does not know (real data often names
    // none): the shipped definition stands in, and the notes say so, since
    // its gains, drive constants and encoder are then assumed, not known.
    const std::string said =
        run.meta.machine ? fmt::format("names machine '{}', which the twin does not ship", *run.meta.machine)
                         : std::string("names no machine");
    name = io::kDefaultMachineName;
    path = io::resolve_machine_path(name);
    if (notes)
      notes->push_back(fmt::format("meta.json {}: the {} definition is assumed (its loop gains, Ka, Kt, rg, Ts, "
                                   "encoder resolution and limits where the run does not give them); pass "
                                   "--machine FILE for the machine the run was made on",
                                   said, name));
  }
  sim::MachineDefinition m = io::load_machine(path);
  if (run.meta.controller_period_s && std::abs(*run.meta.controller_period_s - m.Ts_s) > 1e-12) {
    if (notes)
      notes->push_back(fmt::format("controller period {} s from meta.json replaces the machine's Ts = {} s",
                                   *run.meta.controller_period_s, m.Ts_s));
    m.Ts_s = *run.meta.controller_period_s;
  }
  if (run.meta.encoder_resolution_mm) m.encoder_resolution_mm = *run.meta.encoder_resolution_mm;
  for (Axis a : run.axes)
    if (!m.axes[index(a)].present && sim::machine_loop_law(m) == controller::LoopLaw::kCascade) {
      // A machine identified from data leaves out the axes it could not identify.
      if (notes)
        notes->push_back(fmt::format("axis {}: machine {} does not define it (it was not identified); not replayed",
                                     axis_name(a), m.name));
    } else if (!m.axes[index(a)].present)
      throw ConfigError(fmt::format("{}: the run has axis {} but machine {} does not define it", run.dir.string(),
                                    axis_name(a), m.name));
  return m;
}

std::vector<double> monotone_slopes(const std::vector<double>& r) {
  const std::size_t n = r.size();
  // Secant slopes per sample interval, and at each sample the centred
  // difference (exact through constant acceleration), set to zero where the
  // reference turns or stops and limited to 3 times the smaller secant so
  // that no interval overshoots its end values (Fritsch and Carlson, SIAM
  // J. Numer. Anal. 17 (1980) 238-246).
  std::vector<double> d(n > 1 ? n - 1 : 0), slope(n, 0.0);
  for (std::size_t i = 0; i + 1 < n; ++i) d[i] = r[i + 1] - r[i];
  if (n > 1) {
    slope.front() = d.front();
    slope.back() = d.back();
  }
  for (std::size_t i = 1; i + 1 < n; ++i) {
    if (d[i - 1] * d[i] <= 0.0) continue;
    const double c = 0.5 * (d[i - 1] + d[i]);
    const double lim = 3.0 * std::min(std::abs(d[i - 1]), std::abs(d[i]));
    slope[i] = std::copysign(std::min(std::abs(c), lim), c);
  }
  return slope;
}

std::vector<double> reference_slopes(const std::vector<double>& r, const std::vector<double>& v_mm_s, double dt_s) {
  std::vector<double> slope = monotone_slopes(r);
  const std::size_t n = r.size();
  for (std::size_t i = 0; i < n && i < v_mm_s.size(); ++i) {
    const double s = v_mm_s[i] * dt_s;
    if (!std::isfinite(s)) continue;
    const double before = i > 0 ? r[i] - r[i - 1] : 0.0, after = i + 1 < n ? r[i + 1] - r[i] : 0.0;
    const bool along = s == 0.0 || s * before > 0.0 || s * after > 0.0;
    if (along && std::abs(s) <= 3.0 * std::max(std::abs(before), std::abs(after))) slope[i] = s;
  }
  return slope;
}

std::string reference_speed_column(Axis a) { return std::string(axis_name(a)) + "_ref_v_mm_s"; }

bool shows_reference_speed(const MeasuredRun& run, Axis a, const sim::AxisDefinition& def) {
  const std::string n(axis_name(a));
  const controller::CascadeGains& g = def.loop.cascade;
  return run.sample_period_s > kLawSpeedMinPeriod_s + 1e-12 && run.trace.find(n + "_vcmd_mm_s") != nullptr &&
         run.trace.find(n + "_mm") != nullptr && run.trace.find(n + "_ref_mm") != nullptr &&
         def.loop.law == controller::LoopLaw::kCascade && g.kff >= 0.1 && g.Kv_per_s > 0.0 &&
         g.command_average_s == 0.0 && g.command_lag_s == 0.0 && g.command_delay_s == 0.0;
}

std::vector<double> law_reference_speed(const MeasuredRun& run, Axis a, const sim::AxisDefinition& def) {
  if (!shows_reference_speed(run, a, def)) return {};
  const std::string n(axis_name(a));
  const auto& vcmd = run.trace.at(n + "_vcmd_mm_s");
  const auto& x = run.trace.at(n + "_mm");
  const auto& ref = run.trace.at(n + "_ref_mm");
  const controller::CascadeGains& g = def.loop.cascade;
  std::vector<double> v(ref.size());
  for (std::size_t k = 0; k < v.size(); ++k) v[k] = (vcmd[k] - g.Kv_per_s * (ref[k] - x[k])) / g.kff;
  return v;
}

std::vector<double> upsample_reference(const std::vector<double>& r, std::int64_t m,
                                       const std::vector<double>* slopes) {
  const std::size_t n = r.size();
  if (n == 0 || m <= 1) return r;
  const std::vector<double> slope = slopes != nullptr && slopes->size() == n ? *slopes : monotone_slopes(r);
  std::vector<double> out(static_cast<std::size_t>((static_cast<std::int64_t>(n) - 1) * m + 1));
  for (std::size_t k = 0; k < out.size(); ++k) {
    const std::size_t i = k / static_cast<std::size_t>(m);
    const double f = static_cast<double>(k % static_cast<std::size_t>(m)) / static_cast<double>(m);
    if (f == 0.0) {
      out[k] = r[i];
      continue;
    }
    // Cubic Hermite on [i, i+1] in the unit parameter f.
    const double f2 = f * f, f3 = f2 * f;
    out[k] = (2 * f3 - 3 * f2 + 1) * r[i] + (f3 - 2 * f2 + f) * slope[i] + (-2 * f3 + 3 * f2) * r[i + 1] +
             (f3 - f2) * slope[i + 1];
  }
  return out;
}

/// Controller periods rebuilt between two trace samples: a 1 ms log of a
/// 0.1 ms loop needs 10; 1000 allows a 0.1 s log of that loop.
constexpr std::int64_t kMaxUpsampling = 1000;

namespace {

// Controller periods per trace sample: a whole number, at most kMaxUpsampling.
std::int64_t upsampling(const MeasuredRun& run, double Ts) {
  const double ratio = run.sample_period_s / Ts;
  if (!(ratio < static_cast<double>(kMaxUpsampling) + 0.5))
    throw ConfigError(fmt::format("{}: the trace is sampled every {} s, {:.4g} controller periods of {} s: more than "
                                  "the {} a replay rebuilds between two samples (check controller_period_s in meta.json)",
                                  run.trace.source, run.sample_period_s, ratio, Ts, kMaxUpsampling));
  const auto m = static_cast<std::int64_t>(std::llround(ratio));
  if (m < 1 || std::abs(ratio - static_cast<double>(m)) > 0.01)
    throw ConfigError(fmt::format(
        "{}: the trace is sampled every {} s, which is not a whole multiple of the controller period {} s: the "
        "reference the loop saw cannot be rebuilt",
        run.trace.source, run.sample_period_s, Ts));
  return m;
}

// The reference of every axis at the loop's rate and its start position.
// The machine that made the run did not alarm: the following-error limit of
// the replay is raised to at least twice the run's own largest error.
struct Start {
  AxisArray<std::vector<double>> ref{};
  AxisArray<double> x0{};
  /// Whether an axis's reference was rebuilt through its speed at the samples.
  bool speed_from_law{false};
};
Start replay_start(const MeasuredRun& run, std::size_t n_rows, std::int64_t m, sim::MachineDefinition& machine,
                   ReplayResult& res) {
  Start st;
  for (Axis a : run.axes) {
    const std::string n(axis_name(a));
    const auto& r = run.trace.at(n + "_ref_mm");
    const std::vector<double> rows(r.begin(), r.begin() + static_cast<std::ptrdiff_t>(n_rows));
    // The reference's speed at the samples where the log shows it: carried
    // by the run, else read off a logged velocity command.
    std::vector<double> speed;
    if (const auto* v = run.trace.find(reference_speed_column(a)))
      speed.assign(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(n_rows));
    else if (m > 1)
      speed = law_reference_speed(run, a, machine.axes[index(a)]);
    if (m > 1 && speed.size() >= n_rows) {
      speed.resize(n_rows);
      const std::vector<double> slopes = reference_slopes(rows, speed, run.sample_period_s);
      st.ref[index(a)] = upsample_reference(rows, m, &slopes);
      st.speed_from_law = true;
    } else {
      st.ref[index(a)] = upsample_reference(rows, m);
    }
    const auto* xm = run.trace.find(n + "_mm");
    st.x0[index(a)] = xm ? (*xm)[0] : r[0];
    if (!xm) continue;
    double e_max = 0.0;
    for (std::size_t k = 0; k < std::min(r.size(), xm->size()); ++k) e_max = std::max(e_max, std::abs(r[k] - (*xm)[k]));
    auto& lim = machine.axes[index(a)].following_error_limit_mm;
    if (2.0 * e_max > lim) {
      res.notes.push_back(fmt::format("axis {}: the run's tracking error reaches {:.3f} mm; the replay's following-error "
                                      "limit is raised from {} mm to {:.3f} mm",
                                      n, e_max, lim, 2.0 * e_max));
      lim = 2.0 * e_max;
    }
  }
  return st;
}

/// The time a replay runs before a log that begins in motion: a few time
/// constants of position loops down to Kv = 15 1/s.
constexpr double kRunIn_s = 0.2;
/// The slowest log a run-in is built for: its first rows show the motion
/// within 20 ms of the first. A slower log's first three rows span more than
/// the loop's time constants, and do not tell a move under way at the first
/// row from one that set off within the first sample or two (at 100 ms, the
/// U-Mich logs: a run-in there lost umich13 y, 0.592 to 0.625 against the
/// regression's 0.618, and the y axis's pooled error rose from 0.599 to 0.604).
constexpr double kRunInMaxPeriod_s = 0.01;

/// A log that begins in motion (recorded, or resumed after a stitch or a gap,
/// mid-move) is not replayed from rest: a drive started at rest under a
/// moving command runs a transient the machine never ran. Where a log samples
/// every 10 ms or faster and an axis's first two steps go the same way, and so
/// does its speed at the first row, its reference is extended back by
/// kRunIn_s along the quadratic fitted to its first rows (10 ms of them, 3 to
/// 10 rows). The extension is held where that quadratic comes to rest (a move
/// that started within the run-in; one that started within the sample before
/// the first row is replayed from rest at the first row, as before), or, where
/// it brakes, runs at twice the first row's speed before the braking began.
/// The replay starts there, in steady motion at the extension's speed
/// (sim::start_in_steady_motion), and runs the extension before the log's
/// first row; its outputs are not kept. Other axes hold their first reference
/// through it.
struct RunIn {
  std::int64_t ticks{0};
  AxisArray<std::vector<double>> ref{};  ///< the extension, ticks values per axis
  AxisArray<bool> moving{};               ///< the log begins in motion on the axis
  AxisArray<std::optional<sim::ReferenceAtStart>> start{};  ///< where the extension is in motion at its start
};
RunIn run_in_before(const MeasuredRun& run, std::size_t n_rows, const Start& st, double Ts) {
  RunIn out;
  if (n_rows < 3 || run.sample_period_s > kRunInMaxPeriod_s + 1e-12) return out;
  const auto& t = run.trace.at("t_s");
  const std::size_t K = std::min<std::size_t>(
      n_rows, std::clamp<std::size_t>(static_cast<std::size_t>(std::lround(0.01 / run.sample_period_s)), 3, 10));
  AxisArray<std::optional<std::array<double, 2>>> va{};  // speed and acceleration at the first row
  for (Axis a : run.axes) {
    const auto& r = run.trace.at(std::string(axis_name(a)) + "_ref_mm");
    if (!((r[1] - r[0]) * (r[2] - r[1]) > 0.0)) continue;
    // Least squares of r - r[0] on tau and tau^2 / 2 over the first K rows.
    Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
    Eigen::Vector2d y = Eigen::Vector2d::Zero();
    for (std::size_t k = 1; k < K; ++k) {
      const double tau = t[k] - t[0];
      const Eigen::Vector2d phi(tau, 0.5 * tau * tau);
      A += phi * phi.transpose();
      y += phi * (r[k] - r[0]);
    }
    const Eigen::Vector2d th = A.ldlt().solve(y);
    if (!th.allFinite()) continue;
    // A move under way has its speed the way it steps. One that the
    // quadratic puts the other way at the first row (positions 0, 1, 5: a
    // move that set off inside the first sample), or at rest within the
    // sample before it, is replayed from rest at the first row, as a log that
    // begins at rest.
    if (!(th(0) * (r[1] - r[0]) > 0.0)) continue;
    if (th(0) * th(1) > 0.0 && th(0) / th(1) < run.sample_period_s) continue;
    va[index(a)] = std::array<double, 2>{th(0), th(1)};
  }
  if (std::none_of(va.begin(), va.end(), [](const auto& x) { return x.has_value(); })) return out;
  out.ticks = static_cast<std::int64_t>(std::llround(kRunIn_s / Ts));
  for (Axis a : run.axes) {
    const double x0 = st.ref[index(a)].front();
    auto& ext = out.ref[index(a)];
    ext.assign(static_cast<std::size_t>(out.ticks), x0);
    if (!va[index(a)]) continue;
    out.moving[index(a)] = true;
    const auto [v0, a0] = *va[index(a)];
    // Going back in time, the speed v0 + a0 tau reaches 0 at tau = -v0 / a0
    // where the move accelerates away from rest: before that it stood there.
    // Where it brakes, the speed going back grows; it is taken to have
    // braked as long (from twice the speed), and to have run at that speed
    // before, rather than to grow without bound.
    const double tau_start = a0 != 0.0 ? -std::abs(v0 / a0) : -std::numeric_limits<double>::infinity();
    auto at = [&](double tau) {
      const double te = std::max(tau, tau_start);
      const double x = x0 + v0 * te + 0.5 * a0 * te * te, v = v0 + a0 * te;
      return std::array<double, 2>{x + (tau - te) * v, v};
    };
    for (std::int64_t j = 0; j < out.ticks; ++j)
      ext[static_cast<std::size_t>(j)] = at(-static_cast<double>(out.ticks - j) * Ts)[0];
    const auto first = at(-static_cast<double>(out.ticks) * Ts);
    if (first[1] != 0.0)
      out.start[index(a)] = sim::ReferenceAtStart{first[0], at(-static_cast<double>(out.ticks + 1) * Ts)[0],
                                                  at(-static_cast<double>(out.ticks + 2) * Ts)[0], first[1]};
  }
  return out;
}

void reserve_rows(ReplayResult& res, std::size_t n_rows) {
  res.t_s.reserve(n_rows);
  for (Axis a : res.axes)
    for (auto* v : {&res.x_ref_mm[index(a)], &res.x_mm[index(a)], &res.u_V[index(a)], &res.i_A[index(a)],
                    &res.Tm[index(a)], &res.vcmd_mm_per_s[index(a)]})
      v->reserve(n_rows);
}

// Running sums of the torque-side channels (u, i, Tm) per tick, for
// ChannelSampling::kMeanOverNeighbours: the mean over ticks [a, b] is
// (S[b + 1] - S[a]) / (b - a + 1).
using TickSums = AxisArray<std::array<std::vector<double>, 3>>;

// The current and torque a log holds of an axis at a tick: the motor's, or
// the loop's command before the current loop where the machine says the log
// holds that (AxisDefinition::torque_command_logged); the tick's own, or
// their mean over the period before it where the machine says the log
// averages (AxisDefinition::logged_torque_period_mean).
struct LoggedTorque {
  double i_A{0.0}, T{0.0};
};
LoggedTorque logged_torque(const sim::AxisDefinition& def, const sim::AxisSnapshot& x) {
  const bool mean = def.logged_torque_period_mean != 0.0;
  if (def.torque_command_logged == 0.0)
    return mean ? LoggedTorque{x.period_mean.i_A, x.period_mean.Tm_Nm} : LoggedTorque{x.i_A, x.Tm_Nm};
  const double Tcmd = mean ? x.period_mean.Tcmd_Nm : x.Tcmd_Nm;
  return {Tcmd / def.drive.Kt_Nm_per_A, Tcmd};
}

// The logged torque through the monitor's first-order low-pass where the
// machine has one (AxisDefinition::logged_torque_filter_s), from the first
// tick's value (the monitor settled before the replayed part).
class TorqueMonitor {
 public:
  TorqueMonitor(const sim::AxisDefinition& def, double Ts_s)
      : a_(def.logged_torque_filter_s > 0.0 ? std::exp(-Ts_s / def.logged_torque_filter_s) : 0.0) {}
  LoggedTorque operator()(const LoggedTorque& in) {
    if (!started_) {
      y_ = in;
      started_ = true;
    } else {
      y_.i_A = a_ * y_.i_A + (1.0 - a_) * in.i_A;
      y_.T = a_ * y_.T + (1.0 - a_) * in.T;
    }
    return y_;
  }

 private:
  double a_;
  bool started_{false};
  LoggedTorque y_;
};

// Steps the co-simulation over every tick, keeping the outputs at the trace's
// samples (and the running sums where `sums` is given).
void run_ticks(sim::CoSimulation& cosim, const sim::MachineDefinition& machine, const MeasuredRun& run,
               std::int64_t n_ticks, std::int64_t m, double Ts_s, ReplayResult& res, TickSums* sums) {
  const auto& t = run.trace.at("t_s");
  std::vector<TorqueMonitor> monitor;
  for (Axis a : kAllAxes) monitor.emplace_back(machine.axes[index(a)], Ts_s);
  AxisArray<LoggedTorque> seen{};
  for (std::int64_t k = 0; k < n_ticks; ++k) {
    const sim::Snapshot& s = cosim.step();
    for (Axis a : run.axes) seen[index(a)] = monitor[index(a)](logged_torque(machine.axes[index(a)], s.axes[index(a)]));
    if (sums)
      for (Axis a : run.axes) {
        const auto& x = s.axes[index(a)];
        const LoggedTorque& lt = seen[index(a)];
        auto& S = (*sums)[index(a)];
        S[0].push_back(S[0].back() + x.u_V);
        S[1].push_back(S[1].back() + lt.i_A);
        S[2].push_back(S[2].back() + lt.T);
      }
    if (k % m != 0) continue;
    res.t_s.push_back(t[static_cast<std::size_t>(k / m)]);
    for (Axis a : run.axes) {
      const auto& x = s.axes[index(a)];
      const LoggedTorque& lt = seen[index(a)];
      res.x_ref_mm[index(a)].push_back(x.x_ref_mm);
      res.x_mm[index(a)].push_back(x.x_mm);
      res.u_V[index(a)].push_back(x.u_V);
      res.i_A[index(a)].push_back(lt.i_A);
      res.Tm[index(a)].push_back(lt.T);
      res.vcmd_mm_per_s[index(a)].push_back(x.vcmd_mm_per_s);
    }
  }
}

// u, current and torque at each row as their mean over the ticks of the two
// sample periods around it.
void mean_over_neighbours(const TickSums& sums, const MeasuredRun& run, std::int64_t n_ticks, std::int64_t m,
                          ReplayResult& res) {
  res.notes.push_back(fmt::format("the twin's u, current and torque at a row are their mean over the two sample "
                                  "periods around it ({:.6g} s): where the log samples every {:.6g} s, a stop or a "
                                  "change of speed falls at a time inside them the log does not give",
                                  2.0 * run.sample_period_s, run.sample_period_s));
  for (Axis a : run.axes) {
    const auto& S = sums[index(a)];
    for (std::size_t r = 0; r < res.t_s.size(); ++r) {
      const std::int64_t c = static_cast<std::int64_t>(r) * m;
      const auto lo = static_cast<std::size_t>(std::max<std::int64_t>(c - m, 0));
      const auto hi = static_cast<std::size_t>(std::min<std::int64_t>(c + m, n_ticks - 1));
      const double n_in = static_cast<double>(hi - lo + 1);
      res.u_V[index(a)][r] = (S[0][hi + 1] - S[0][lo]) / n_in;
      res.i_A[index(a)][r] = (S[1][hi + 1] - S[1][lo]) / n_in;
      res.Tm[index(a)][r] = (S[2][hi + 1] - S[2][lo]) / n_in;
    }
  }
}

/// A run with gaps in its clock, replayed part by part, each from its own
/// start (the loop cannot be followed through time the log does not hold).
/// A part of fewer than 3 rows is not replayed: the twin is put on its
/// command there, with no output, and a note says so.
ReplayResult replay_parts(const MeasuredRun& run, const sim::MachineDefinition& machine, std::size_t n_rows,
                          feeddrive::IntegratorOptions options, ChannelSampling sampling) {
  ReplayResult res;
  res.axes = run.axes;
  std::vector<std::size_t> bounds{0};
  for (std::size_t b : run.time_breaks)
    if (b < n_rows) bounds.push_back(b);
  bounds.push_back(n_rows);
  const auto& t = run.trace.at("t_s");
  AxisArray<const std::vector<double>*> refs{};
  for (Axis a : run.axes) refs[index(a)] = &run.trace.at(std::string(axis_name(a)) + "_ref_mm");
  std::size_t unreplayed = 0;
  for (std::size_t p = 0; p + 1 < bounds.size(); ++p) {
    const std::size_t b = bounds[p], e = bounds[p + 1];
    if (e - b < 3) {
      unreplayed += e - b;
      for (std::size_t k = b; k < e; ++k) {
        res.t_s.push_back(t[k]);
        for (Axis a : run.axes) {
          const double r = (*refs[index(a)])[k];
          res.x_ref_mm[index(a)].push_back(r);
          res.x_mm[index(a)].push_back(r);
          for (auto* v : {&res.u_V, &res.i_A, &res.Tm, &res.vcmd_mm_per_s}) (*v)[index(a)].push_back(0.0);
        }
      }
      continue;
    }
    const ReplayResult r = replay_run(rows_of(run, b, e), machine, 0, options, sampling);
    res.t_s.insert(res.t_s.end(), r.t_s.begin(), r.t_s.end());
    for (Axis a : run.axes)
      for (auto m : {&ReplayResult::x_ref_mm, &ReplayResult::x_mm, &ReplayResult::u_V, &ReplayResult::i_A,
                     &ReplayResult::Tm, &ReplayResult::vcmd_mm_per_s}) {
        auto& dst = (res.*m)[index(a)];
        const auto& src = (r.*m)[index(a)];
        dst.insert(dst.end(), src.begin(), src.end());
      }
    for (const auto& note : r.notes)
      if (std::find(res.notes.begin(), res.notes.end(), note) == res.notes.end()) res.notes.push_back(note);
  }
  if (unreplayed > 0)
    res.notes.push_back(fmt::format("{} rows between two gaps of t_s are too few to replay: the twin is put on its "
                                    "command there, with no output",
                                    unreplayed));
  return res;
}

}  // namespace

MeasuredRun rows_of(const MeasuredRun& run, std::size_t begin, std::size_t end,
                    const std::vector<std::string>& names) {
  MeasuredRun part;
  part.dir = run.dir;
  part.meta = run.meta;
  part.axes = run.axes;
  part.sample_period_s = run.sample_period_s;
  part.log_rows_per_loop_period = run.log_rows_per_loop_period;
  part.loop_period_seen_in = run.loop_period_seen_in;
  part.loop_period_share = run.loop_period_share;
  part.trace.source = run.trace.source;
  for (std::size_t c = 0; c < run.trace.names.size(); ++c) {
    if (!names.empty() && std::find(names.begin(), names.end(), run.trace.names[c]) == names.end()) continue;
    part.trace.names.push_back(run.trace.names[c]);
    part.trace.columns.emplace_back(run.trace.columns[c].begin() + static_cast<std::ptrdiff_t>(begin),
                                    run.trace.columns[c].begin() + static_cast<std::ptrdiff_t>(end));
  }
  return part;
}

ReplayResult replay_run(const MeasuredRun& run, const sim::MachineDefinition& machine_in, std::size_t rows,
                        feeddrive::IntegratorOptions options, ChannelSampling sampling) {
  if (!run.time_breaks.empty())
    return replay_parts(run, machine_in, rows == 0 ? run.trace.num_rows() : std::min(rows, run.trace.num_rows()),
                        options, sampling);
  ReplayResult res;
  res.axes = run.axes;
  sim::MachineDefinition machine = machine_in;
  // Only the run's axes are simulated.
  for (Axis a : kAllAxes)
    if (std::find(run.axes.begin(), run.axes.end(), a) == run.axes.end()) machine.axes[index(a)].present = false;
  const double Ts = machine.Ts_s;
  const std::int64_t m = upsampling(run, Ts);
  const std::size_t n_rows = rows == 0 ? run.trace.num_rows() : std::min(rows, run.trace.num_rows());
  const std::int64_t n_ticks = static_cast<std::int64_t>(n_rows - 1) * m + 1;
  Start st = replay_start(run, n_rows, m, machine, res);
  if (m > 1)
    res.notes.push_back(fmt::format(
        "trace sampled every {:.6g} s = {} controller periods: the reference is interpolated by {} to Ts = {} s and "
        "the twin's outputs are taken at the trace's samples",
        run.sample_period_s, m,
        st.speed_from_law ? "a cubic through its speed at each sample as the logged velocity command shows it under "
                            "the machine's position loop, (vcmd - Kv e) / kff, where that goes the way of the "
                            "samples about it (else a monotone cubic's slope)"
                          : "a monotone cubic",
        Ts));
  const RunIn run_in = run_in_before(run, n_rows, st, Ts);
  AxisArray<double> x0 = st.x0;
  if (run_in.ticks > 0)
    for (Axis a : run.axes) {
      auto& ref = st.ref[index(a)];
      ref.insert(ref.begin(), run_in.ref[index(a)].begin(), run_in.ref[index(a)].end());
      if (run_in.moving[index(a)]) x0[index(a)] = ref.front();
    }
  auto reference = std::make_shared<sim::SampledReference>(std::move(st.ref), Ts);
  sim::CoSimulation cosim(machine, reference, nullptr, x0, options);
  if (std::any_of(run_in.start.begin(), run_in.start.end(), [](const auto& r) { return r.has_value(); }))
    sim::start_in_steady_motion(cosim, run_in.start, 0);
  for (std::int64_t k = 0; k < run_in.ticks; ++k) cosim.step();
  reserve_rows(res, n_rows);
  const bool window = sampling == ChannelSampling::kMeanOverNeighbours && m > 1;
  TickSums sums{};
  if (window)
    for (Axis a : run.axes)
      for (auto& v : sums[index(a)]) {
        v.reserve(static_cast<std::size_t>(n_ticks) + 1);
        v.push_back(0.0);
      }
  run_ticks(cosim, machine, run, n_ticks, m, Ts, res, window ? &sums : nullptr);
  if (window) mean_over_neighbours(sums, run, n_ticks, m, res);
  return res;
}

void write_replay_trace(const std::filesystem::path& path, const ReplayResult& r) {
  std::vector<std::string> names{"t_s"};
  for (Axis a : r.axes) {
    const std::string n(axis_name(a));
    names.insert(names.end(), {n + "_ref_mm", n + "_mm", n + "_u_V", n + "_i_A"});
  }
  io::TraceWriter w(path, names);
  std::vector<double> row;
  for (std::size_t i = 0; i < r.t_s.size(); ++i) {
    row.clear();
    row.push_back(r.t_s[i]);
    for (Axis a : r.axes)
      row.insert(row.end(), {r.x_ref_mm[index(a)][i], r.x_mm[index(a)][i], r.u_V[index(a)][i], r.i_A[index(a)][i]});
    w.write_row(row);
  }
  w.commit();
}

}  // namespace twin::analysis
