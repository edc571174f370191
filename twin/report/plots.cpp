#include "twin/report/plots.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::analysis {

namespace {

bool plain_name(std::string_view name) {
  if (name.empty() || name.front() == '.') return false;
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
                    c == '-' || c == '.';
    if (!ok) return false;
  }
  return true;
}

// The gnuplot executable on PATH, or empty.
std::string find_gnuplot() {
  const char* path = std::getenv("PATH");
  std::string dirs = path != nullptr ? path : "/usr/local/bin:/usr/bin:/bin";
  std::size_t pos = 0;
  while (pos <= dirs.size()) {
    const std::size_t colon = dirs.find(':', pos);
    std::string dir = dirs.substr(pos, colon == std::string::npos ? std::string::npos : colon - pos);
    if (dir.empty()) dir = ".";
    const std::string candidate = dir + "/gnuplot";
    struct stat st {};
    if (::stat(candidate.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(candidate.c_str(), X_OK) == 0)
      return candidate;
    if (colon == std::string::npos) break;
    pos = colon + 1;
  }
  return {};
}

// Runs `exe` with argv {"gnuplot", script_name} in `dir`, stdout and stderr to `log_name`.
// Returns the wait status, or -1 if the process could not be started.
int exec_gnuplot(const std::string& exe, const std::filesystem::path& dir, const char* script_name,
                 const char* log_name) {
  // Block the signals the cleanup handler takes while forking, so that the child
  // is registered (and killed by the handler) before any of them can arrive.
  sigset_t block, old;
  sigemptyset(&block);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&block, sig);
  ::sigprocmask(SIG_BLOCK, &block, &old);
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Child: only async-signal-safe calls until exec.
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) ::signal(sig, SIG_DFL);
    ::sigprocmask(SIG_SETMASK, &old, nullptr);
    if (::chdir(dir.c_str()) != 0) ::_exit(126);
    const int in = ::open("/dev/null", O_RDONLY);
    const int log = ::open(log_name, O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (in < 0 || log < 0) ::_exit(126);
    ::dup2(in, 0);
    ::dup2(log, 1);
    ::dup2(log, 2);
    char arg0[] = "gnuplot";
    std::array<char*, 3> argv{arg0, const_cast<char*>(script_name), nullptr};
    ::execv(exe.c_str(), argv.data());
    ::_exit(127);
  }
  if (pid < 0) {
    ::sigprocmask(SIG_SETMASK, &old, nullptr);
    return -1;
  }
  io::ChildGuard child(pid);
  ::sigprocmask(SIG_SETMASK, &old, nullptr);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -1;
  }
  return status;
}

}  // namespace

std::string gnuplot_file(std::string_view name) {
  if (!plain_name(name))
    throw InternalError(fmt::format("gnuplot: '{}' is not a plain file name", gnuplot_text(name)));
  return "'" + std::string(name) + "'";
}

std::string gnuplot_text(std::string_view text) {
  std::string s = "'";
  for (char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\'') s += "''";
    else if (u < 0x20 || u >= 0x7f) s += '?';
    else s += c;
  }
  return s + "'";
}

std::string gnuplot_output(std::string_view final_name) {
  return gnuplot_file(std::string(final_name) + ".tmp.png");
}

void run_gnuplot(const std::filesystem::path& work_dir, const std::string& script,
                 const std::vector<std::string>& outputs) {
  for (const auto& o : outputs) static_cast<void>(gnuplot_file(o));
  constexpr const char* kScript = "plot-script.gp.tmp";
  constexpr const char* kLog = "plot-log.txt.tmp";
  const auto script_path = work_dir / kScript;
  const auto log_path = work_dir / kLog;
  std::vector<io::TempPathGuard> guards;
  guards.emplace_back(script_path);
  guards.emplace_back(log_path);
  for (const auto& o : outputs) guards.emplace_back(work_dir / (o + ".tmp.png"));
  std::error_code ec;
  auto remove_temporaries = [&] {
    std::filesystem::remove(script_path, ec);
    std::filesystem::remove(log_path, ec);
    for (const auto& o : outputs) std::filesystem::remove(work_dir / (o + ".tmp.png"), ec);
  };
  {
    std::ofstream f(script_path);
    f << script;
    if (!f) {
      remove_temporaries();
      throw IoError(fmt::format("cannot write {}", script_path.string()));
    }
  }
  const std::string exe = find_gnuplot();
  const int rc = exe.empty() ? -1 : exec_gnuplot(exe, work_dir, kScript, kLog);
  std::string first_error;
  {
    std::ifstream lf(log_path);
    for (std::string line; std::getline(lf, line);) {
      if (line.find("rror") != std::string::npos || line.find("not found") != std::string::npos) {
        first_error = line;
        break;
      }
    }
  }
  const bool ok = rc != -1 && WIFEXITED(rc) && WEXITSTATUS(rc) == 0;
  for (const auto& o : outputs) {
    if (!ok || !std::filesystem::exists(work_dir / (o + ".tmp.png"))) {
      remove_temporaries();
      throw IoError(fmt::format("gnuplot could not draw {}: {}", o,
                                exe.empty() ? std::string("gnuplot is not installed (not on PATH)")
                                : !first_error.empty() ? first_error
                                : ok                   ? std::string("no output")
                                                       : std::string("gnuplot failed")));
    }
  }
  for (const auto& o : outputs) {
    std::filesystem::rename(work_dir / (o + ".tmp.png"), work_dir / o, ec);
    if (ec) {
      const std::string msg = ec.message();
      remove_temporaries();
      throw IoError(fmt::format("cannot rename {}: {}", (work_dir / (o + ".tmp.png")).string(), msg));
    }
  }
  remove_temporaries();
}

namespace {
/// The views of the first corner: the zoom of the time plots, and the XY path
/// and the force along it of corner_path.png (times in s).
struct CornerViews {
  double zoom0_s{0.0}, zoom1_s{0.0};   ///< +-0.25 s or the corner's window, whichever is wider
  double half_mm{0.0};                  ///< half-width of the XY view: the blend and a little of the lines around it
  double path0_s{0.0}, path1_s{0.0};   ///< the blend and long enough on either side to leave the XY view
  double force0_s{0.0}, force1_s{0.0}; ///< force along the path: +-0.5 s
  /// The hull of all three: the rows the corner views draw.
  double begin_s() const { return std::min({zoom0_s, path0_s, force0_s}); }
  double end_s() const { return std::max({zoom1_s, path1_s, force1_s}); }
};

CornerViews corner_views(const CornerWindow& w) {
  const controller::Corner& c = w.corner;
  CornerViews v;
  v.zoom0_s = std::min(c.t_s - 0.25, w.t_begin_s - 0.05);
  v.zoom1_s = std::max(c.t_s + 0.25, w.t_end_s + 0.05);
  v.half_mm = std::max({0.1, 4.0 * c.deviation_mm, 2.0 * c.blend_radius_mm});
  const double speed = std::max(c.v_ref_mm_per_s, 1e-3);
  v.path0_s = std::min(c.t_blend_begin_s, c.t_s - 3.0 * v.half_mm / speed) - 0.05;
  v.path1_s = std::max(c.t_blend_end_s, c.t_s + 3.0 * v.half_mm / speed) + 0.05;
  v.force0_s = c.t_s - 0.5;
  v.force1_s = c.t_s + 0.5;
  return v;
}

/// corner_path.png: the XY path through a corner and the force along it.
/// Every number in the script is formatted here; the only file is T.
std::string corner_path_script(const std::string& T, const controller::Trajectory& traj, const CornerWindow& w,
                               bool cutting) {
  const controller::Corner& c = w.corner;
  const double px = c.p_mm[0], py = c.p_mm[1];
  const CornerViews views = corner_views(w);
  const double half_mm = views.half_mm;
  const double v = std::max(c.v_ref_mm_per_s, 1e-3);
  const double t0 = views.path0_s, t1 = views.path1_s;
  const double tf0 = views.force0_s, tf1 = views.force1_s;
  std::ostringstream g;
  // The programmed corner: the reference where the blend starts and ends lies
  // on the programmed moves; the corner point between them.
  const auto a = traj.at_time(std::max(0.0, c.t_s - 3.0 * half_mm / v)).x_mm;
  const auto b = traj.at_time(c.t_s + 3.0 * half_mm / v).x_mm;
  g << "$programmed << EOD\n"
    << fmt::format("{:.9f},{:.9f}\n{:.9f},{:.9f}\n{:.9f},{:.9f}\n", a[0], a[1], px, py, b[0], b[1]) << "EOD\n";
  g << "$blend << EOD\n";
  const double tb0 = c.t_blend_begin_s, tb1 = c.t_blend_end_s;
  for (int i = 0; i <= 200 && tb1 > tb0; ++i) {
    const auto x = traj.at_time(tb0 + (tb1 - tb0) * i / 200.0).x_mm;
    g << fmt::format("{:.9f},{:.9f}\n", x[0], x[1]);
  }
  g << "EOD\n";
  const std::string in_view = fmt::format("(column('t_s') >= {:.6f} && column('t_s') <= {:.6f})", t0, t1);
  const std::string force = "sqrt(column('fx_avg_N')**2 + column('fy_avg_N')**2 + column('fz_avg_N')**2)";
  // (Datablocks use the trace's comma separator.)
  g << "set output " << gnuplot_output("corner_path.png") << "\n"
    << "unset arrow\nunset label\n"
    << "set multiplot layout 1,2\n"
    << "set title " << gnuplot_text(fmt::format("Corner 1, line {}: blend R {:.4f} mm, {:.4f} mm off, {:.0f} mm/min",
                                                w.line_after, c.blend_radius_mm, c.deviation_mm,
                                                c.v_ref_mm_per_s * 60.0))
    << "\n"
    << "set size ratio -1\nset xlabel 'x [mm]'\nset ylabel 'y [mm]'\n"
    << fmt::format("set xrange [{:.9f}:{:.9f}]\nset yrange [{:.9f}:{:.9f}]\n", px - half_mm, px + half_mm,
                   py - half_mm, py + half_mm)
    << (cutting ? "set cblabel 'force (tick mean) [N]'\nset palette rgb 33,13,10\n" : "unset colorbox\n")
    << "plot $programmed using 1:2 with linespoints lw 1 dt 2 lc rgb '#999999' title 'programmed', "
    << "$blend using 1:2 with lines lw 3 lc rgb '#1f77b4' title 'planned blend', " << T << " using ("
    << in_view << " ? column('x_ref_mm') : NaN):'y_ref_mm' with lines lw 1 lc rgb '#000000' title 'reference', ''"
    << " using (" << in_view << " ? column('x_true_mm') : NaN):'y_true_mm'"
    << (cutting ? ":(" + force + ") with lines lw 2 lc palette title 'real (drives), colour: force'"
                : " with lines lw 2 lc rgb '#d62728' title 'real (drives)'")
    << "\n"
    << "set size noratio\nset autoscale x\nset autoscale y\nunset colorbox\n"
    << "set title " << gnuplot_text("Along the path (negative: before the corner)") << "\n"
    << "set xlabel 'distance from the corner point [mm]'\n";
  const std::string dist = fmt::format(
      "(column('t_s') >= {:.6f} && column('t_s') <= {:.6f} ? sgn(column('t_s') - {:.6f}) * "
      "sqrt((column('x_true_mm') - {:.9f})**2 + (column('y_true_mm') - {:.9f})**2) : NaN)",
      tf0, tf1, c.t_s, px, py);
  if (cutting) {
    g << "set ylabel 'force [N]'\nset y2label 'engagement [deg]'\nset y2tics\nset ytics nomirror\n"
      << "set y2range [0:*]\n"
      << "plot " << T << " using " << dist << ":(" << force
      << ") with lines lc rgb '#d62728' title 'force (tick mean)', '' using " << dist
      << ":'engagement_deg' axes x1y2 with lines lc rgb '#ff7f0e' title 'engagement'\n";
  } else {
    g << "set ylabel 'feed [mm/min]'\n"
      << "plot " << T << " using " << dist << ":'feed_ref_mm_per_min' with lines lc rgb '#1f77b4' title 'reference', "
      << "'' using " << dist << ":'feed_mm_per_min' with lines lc rgb '#d62728' title 'real (drives)'\n";
  }
  g << "unset multiplot\nunset y2tics\nunset y2label\nset ytics mirror\nset autoscale\n";
  return g.str();
}
}  // namespace

namespace {
/// The rows the plots draw, written once so gnuplot does not parse the whole
/// trace for every curve: `full` holds every n-th of the trace's `rows` data
/// rows (about 20000, the whole run's view), `window` every row with t_s in
/// [w0, w1] (the corner views). Both keep the header.
void write_plot_rows(const std::filesystem::path& trace, std::size_t rows, const std::filesystem::path& full,
                     const std::filesystem::path& window, double w0, double w1) {
  const std::size_t every = rows > 20000 ? rows / 20000 : 1;
  std::ifstream in(trace, std::ios::binary);
  if (!in) throw IoError(fmt::format("cannot read {} for the plots", trace.string()));
  std::ofstream f(full, std::ios::binary), w(window, std::ios::binary);
  std::string line;
  if (std::getline(in, line)) f << line << '\n', w << line << '\n';
  for (std::size_t i = 0; std::getline(in, line); ++i) {
    if (line.empty()) continue;
    if (i % every == 0) f << line << '\n';
    if (w1 >= w0) {
      const double t = std::strtod(line.c_str(), nullptr);
      if (t >= w0 && t <= w1) w << line << '\n';
    }
  }
  if (!f || !w) throw IoError(fmt::format("cannot write the plots' rows beside {}", trace.string()));
}
}  // namespace

namespace {

/// The two row files of write_plot_rows in the staging folder, removed when done.
class PlotRows {
 public:
  explicit PlotRows(const std::filesystem::path& dir)
      : full_(dir / "plot-rows-full.csv"), window_(dir / "plot-rows-corner.csv"), full_guard_(full_),
        window_guard_(window_) {}
  ~PlotRows() {
    std::error_code ec;
    std::filesystem::remove(full_, ec);
    std::filesystem::remove(window_, ec);
  }
  PlotRows(const PlotRows&) = delete;
  PlotRows& operator=(const PlotRows&) = delete;
  const std::filesystem::path& full() const { return full_; }
  const std::filesystem::path& window() const { return window_; }

 private:
  std::filesystem::path full_, window_;
  io::TempPathGuard full_guard_, window_guard_;
};

/// A dashed line and a label at every corner.
std::string corner_marks(const std::vector<CornerWindow>& corners) {
  std::ostringstream marks;
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const double t = corners[c].corner.t_s;
    marks << fmt::format("set arrow {} from {:.6f}, graph 0 to {:.6f}, graph 1 nohead dt 2 lc rgb '#888888'\n", c + 1,
                         t, t);
    marks << fmt::format("set label {} 'corner {}: {:.0f} deg, line {}' at {:.6f}, graph 0.97 rotate by 90 right "
                         "font ',9'\n",
                         c + 1, c + 1, corners[c].corner.turn_angle_deg, corners[c].line_after, t);
  }
  return marks.str();
}

/// One figure: the whole run on top and, with a `zoom` (an xrange), the first
/// corner's window below.
void figure(std::ostringstream& g, const std::string& zoom, const std::string& out, const std::string& title,
            const std::string& setup, const std::string& plot_full, const std::string& plot_zoom) {
  g << "set output " << gnuplot_output(out) << "\n";
  if (!zoom.empty()) g << "set multiplot layout 2,1\n";
  g << setup << "set title " << gnuplot_text(title) << "\nset autoscale x\n" << plot_full << "\n";
  if (!zoom.empty())
    g << "set title " << gnuplot_text(title + ", around corner 1") << "\n" << zoom << plot_zoom << "\nunset multiplot\n";
  g << "set autoscale x\nunset y2tics\nunset y2label\nset ytics mirror\n";
}

std::string feed_plot(const std::string& file) {
  return "plot " + file +
         " using 't_s':'feed_programmed_mm_per_min' with lines lw 2 lc rgb '#999999' title 'programmed', '' "
         "using 't_s':'feed_ref_mm_per_min' with lines lw 2 lc rgb '#1f77b4' title 'interpolator "
         "reference', '' using 't_s':'feed_mm_per_min' with lines lw 1 lc rgb '#d62728' title "
         "'real (drives)'";
}

std::string error_plot(const std::string& file, const std::vector<Axis>& axes) {
  const std::array<const char*, 3> colours{"#1f77b4", "#2ca02c", "#9467bd"};
  std::string p = "plot ";
  for (std::size_t i = 0; i < axes.size(); ++i) {
    const std::string n(axis_name(axes[i]));
    p += (i ? ", " : "") + file + " using 't_s':(column('" + n + "_err_mm')*1000) with lines lc rgb '" +
         colours[i % 3] + "' title '" + n + " tracking error'";
  }
  return p + ", ''" +
         " using 't_s':(column('contour_error_mm')*1000) with lines lw 2 lc rgb '#d62728' title 'contour error'";
}

std::string force_plot(const std::string& file) {
  return "plot " + file + " using 't_s':'fx_avg_N' with lines lc rgb '#1f77b4' title 'fx (tick mean)', ''" +
         " using 't_s':'fy_avg_N' with lines lc rgb '#2ca02c' title 'fy (tick mean)', ''" +
         " using 't_s':'fz_avg_N' with lines lc rgb '#9467bd' title 'fz (tick mean)', ''" +
         " using 't_s':'engagement_deg' axes x1y2 with lines lc rgb '#ff7f0e' title 'engagement'";
}

}  // namespace

std::vector<std::filesystem::path> plot_run(io::ResultSet& results, const std::string& trace_name,
                                            std::size_t rows, const std::vector<Axis>& axes, const std::vector<CornerWindow>& corners,
                                            bool cutting, const controller::Trajectory* trajectory) {
  std::vector<std::string> outputs{"feedrate.png", "errors.png"};
  if (cutting) outputs.push_back("forces.png");
  const bool has_xy = std::find(axes.begin(), axes.end(), Axis::kX) != axes.end() &&
                      std::find(axes.begin(), axes.end(), Axis::kY) != axes.end();
  const bool path_view = trajectory != nullptr && !corners.empty() && has_xy;
  if (path_view) outputs.push_back("corner_path.png");
  // Full-rate rows only where the first corner's views draw them.
  const bool corner_view = !corners.empty();
  const CornerViews views = corner_view ? corner_views(corners.front()) : CornerViews{};
  const double w0 = corner_view ? views.begin_s() : 1.0, w1 = corner_view ? views.end_s() : 0.0;
  const PlotRows plot_rows(results.staging_dir());
  write_plot_rows(results.staging_dir() / trace_name, rows, plot_rows.full(), plot_rows.window(), w0, w1);
  // The full view draws about 20000 rows a curve (T); the corner zoom every row (W).
  const std::string T = gnuplot_file(plot_rows.full().filename().string());
  const std::string W = gnuplot_file(plot_rows.window().filename().string());
  std::ostringstream g;
  g << "set datafile separator ','\n"
    << "set terminal pngcairo size 1400,1000 font 'DejaVu Sans,11' noenhanced\n"
    << "set key outside top center horizontal\n"
    << "set grid\n"
    << "set xlabel 'time [s]'\n";
  g << corner_marks(corners);
  // Each figure: the whole run on top and, when the program has corners, the
  // first corner's window below (+-0.25 s or the window, whichever is wider).
  const std::string zoom =
      corner_view ? fmt::format("set xrange [{:.6f}:{:.6f}]\n", views.zoom0_s, views.zoom1_s) : std::string();
  figure(g, zoom, outputs[0], "Feedrate (dashed lines: corners)", "set ylabel 'feed [mm/min]'\n", feed_plot(T),
         feed_plot(W));
  figure(g, zoom, outputs[1], "Tracking error per axis and contour error", "set ylabel 'error [um]'\n",
         error_plot(T, axes), error_plot(W, axes));
  if (cutting) {
    figure(g, zoom, outputs[2], "Cutting force on the workpiece and engagement",
           "set ylabel 'force [N]'\nset y2label 'engagement [deg]'\nset y2tics\nset ytics nomirror\n"
           "set y2range [0:*]\n",
           force_plot(T), force_plot(W));
    g << "set autoscale y2\n";
  }
  if (path_view) g << corner_path_script(W, *trajectory, corners.front(), cutting);
  g << "unset output\n";
  std::vector<std::filesystem::path> written;
  for (const auto& o : outputs) written.push_back(results.path(o));
  run_gnuplot(results.staging_dir(), g.str(), outputs);
  return written;
}

std::vector<std::filesystem::path> plot_calibration(io::ResultSet& results, const std::string& residuals_name,
                                                    const std::vector<Axis>& axes,
                                                    const std::optional<CalibrationEvidence>& evidence) {
  const std::string d = gnuplot_file(residuals_name);
  std::string script = "set datafile separator ','\nset key autotitle columnhead\nset grid\n";
  std::vector<std::string> outputs;
  const std::size_t na = axes.size();
  for (const std::string which : {"before", "after"}) {
    const std::string png = fmt::format("residual_{}.png", which);
    outputs.push_back(png);
    script += fmt::format("set terminal pngcairo size 1200,{} noenhanced\nset output {}\nset multiplot layout {},2\n",
                          300 * na, gnuplot_output(png), na);
    for (std::size_t j = 0; j < na; ++j) {
      const std::size_t c0 = 2 + 5 * j;  // gnuplot columns are 1-based: t_s is 1
      const std::string an(axis_name(axes[j]));
      const std::size_t ce = c0 + (which == "before" ? 1 : 2);
      const std::size_t cu = c0 + (which == "before" ? 3 : 4);
      script += fmt::format("set title {}\nset xlabel 't s'\nset ylabel 'mm'\nplot {} using 1:{} with lines notitle\n",
                            gnuplot_text(fmt::format("{} tracking error, measured minus model ({})", an, which)), d,
                            ce);
      script += fmt::format("set title {}\nset ylabel 'V (or A)'\nplot {} using 1:{} with lines notitle\n",
                            gnuplot_text(fmt::format("{} low-passed u, measured minus model ({})", an, which)), d,
                            cu);
    }
    script += "unset multiplot\n";
  }
  if (evidence && evidence->axis_slot < na) {
    const std::size_t c0 = 2 + 5 * evidence->axis_slot;
    const std::string png = "evidence.png";
    outputs.push_back(png);
    const std::string xlabel = evidence->over_position ? fmt::format("{} mm", axis_name(evidence->axis)) : "t s";
    const std::size_t cx = evidence->over_position ? c0 : 1;
    script += fmt::format("set terminal pngcairo size 1200,500 noenhanced\nset output {}\nset multiplot layout 1,2\n",
                          gnuplot_output(png));
    script += fmt::format("set title {}\nset xlabel {}\nset ylabel 'V (or A)'\nplot {} using {}:{} with dots notitle\n",
                          gnuplot_text(fmt::format("{} on {}: low-passed u residual of the model without it",
                                                   evidence->effect, axis_name(evidence->axis))),
                          gnuplot_text(xlabel), d, cx, c0 + 3);
    script += fmt::format("set title 'tracking-error residual, without (red) and with (blue) it'\nset xlabel {}\n"
                          "set ylabel 'mm'\nplot {} using {}:{} with dots lc rgb 'red' notitle, '' using {}:{} with "
                          "dots lc rgb 'blue' notitle\nunset multiplot\n",
                          gnuplot_text(xlabel), d, cx, c0 + 1, cx, c0 + 2);
  }
  std::vector<std::filesystem::path> written;
  for (const auto& o : outputs) written.push_back(results.path(o));
  run_gnuplot(results.staging_dir(), script, outputs);
  return written;
}

namespace {

/// bode.png: |L| and |S|, then arg L, of every axis before and after tuning.
std::string bode_script(const TunePlots& p) {
  std::string script = fmt::format("set output {}\n", gnuplot_output("bode.png"));
  script += "set multiplot layout 2,1\nset logscale x\nset grid\nset xlabel 'f [Hz]'\nset ylabel 'dB'\n";
  script += fmt::format("set title {}\n",
                        gnuplot_text(fmt::format("Open loop L (broken at the command), {}: before and after tuning",
                                                 p.machine_name)));
  std::string mag = "plot ", ph = "plot ";
  int idx = 0;
  for (Axis axis : p.axes) {
    for (const char* when : {"before", "after"}) {
      const std::string label = fmt::format("{} {}", axis_name(axis), when);
      if (idx > 0) {
        mag += ", ";
        ph += ", ";
      }
      mag += fmt::format("{} index {} using 1:2 with lines title {}, '' index {} using 1:4 with lines dt 2 "
                         "title {}",
                         gnuplot_file(p.bode_name), idx, gnuplot_text("|L| " + label), idx,
                         gnuplot_text("|S| " + label));
      ph += fmt::format("{} index {} using 1:3 with lines title {}", gnuplot_file(p.bode_name), idx,
                        gnuplot_text("arg L " + label));
      ++idx;
    }
  }
  return script + mag + "\nset ylabel 'deg'\nset title 'Phase of L'\n" + ph + "\nunset multiplot\n";
}

/// corner_error.png: tracking error per axis, then the contour error, before and after.
std::string corner_error_script(const TunePlots& p) {
  const std::string dat = gnuplot_file(p.corner_name);
  std::string script = fmt::format("set output {}\nset multiplot layout 2,1\nunset logscale x\nset xlabel 't [s]'\n",
                                   gnuplot_output("corner_error.png"));
  script += fmt::format("set ylabel 'um'\nset title {}\nplot ", gnuplot_text(p.corner_title));
  int col = 2;
  bool first = true;
  for (Axis axis : p.axes) {
    if (!first) script += ", ";
    first = false;
    script += fmt::format("{} using 1:{} with lines title '{} before', '' using 1:{} with lines title '{} after'", dat,
                          col, axis_name(axis), col + 1, axis_name(axis));
    col += 2;
  }
  script += fmt::format("\nset title 'Contour error'\nplot {} using 1:{} with lines title 'before', '' using 1:{} "
                        "with lines title 'after'\nunset multiplot\n",
                        dat, col, col + 1);
  return script;
}

}  // namespace

std::vector<std::filesystem::path> plot_tuning(io::ResultSet& results, const TunePlots& plots) {
  std::vector<std::string> outputs{"bode.png"};
  std::string script = "set terminal pngcairo size 1200,900 noenhanced\n" + bode_script(plots);
  if (!plots.corner_title.empty()) {
    script += corner_error_script(plots);
    outputs.push_back("corner_error.png");
  }
  script += "unset output\n";
  std::vector<std::filesystem::path> written;
  for (const auto& o : outputs) written.push_back(results.path(o));
  run_gnuplot(results.staging_dir(), script, outputs);
  return written;
}

namespace {

/// One plot of `d`: column `measured` (grey) and `twin` (blue) against column `x`, drawn `with` (lines or points).
std::string measured_and_twin(const std::string& d, std::size_t x, std::size_t measured, std::size_t twin,
                              const char* with) {
  return fmt::format("plot {0} using {1}:{2} with {4} lc rgb '#999999' title 'measured', '' using {1}:{3} with {4} "
                     "lc rgb 'blue' title 'twin'\n",
                     d, x, measured, twin, with);
}

}  // namespace

std::vector<std::filesystem::path> plot_data_calibration(io::ResultSet& results, const DataCalibrationPlots& plots) {
  const std::string d = gnuplot_file(plots.overlay_name);
  const std::size_t n = plots.axes.size();
  std::string script = "set datafile separator ','\nset key autotitle columnhead\nset grid\n";
  script += fmt::format("set terminal pngcairo size 1400,{} noenhanced\nset output {}\nset multiplot layout {},1\n",
                        380 * 2 * n, gnuplot_output("overlay.png"), 2 * n);
  script += fmt::format("set arrow 1 from {0},graph 0 to {0},graph 1 nohead dt 2 lc rgb 'black'\n", plots.t_split_s);
  for (std::size_t j = 0; j < n; ++j) {
    const std::size_t c0 = 2 + 5 * j;
    const auto& ax = plots.axes[j];
    script += fmt::format("set title {}\nset xlabel 't s'\nset ylabel {}\n",
                          gnuplot_text(fmt::format("{} {}: measured (grey) and twin (blue); fitted left of "
                                                   "the dashed line, held out right of it",
                                                   ax.name, ax.channel)),
                          gnuplot_text(ax.unit));
    script += measured_and_twin(d, 1, c0, c0 + 1, "lines");
    script += fmt::format("set title {}\nset ylabel 'mm'\n",
                          gnuplot_text(ax.name + " following error: measured (grey) and twin (blue)"));
    script += measured_and_twin(d, 1, c0 + 2, c0 + 3, "lines");
  }
  script += "unset multiplot\nunset arrow 1\n";
  script += fmt::format("set terminal pngcairo size 1200,{} noenhanced\nset output {}\nset multiplot layout {},1\n",
                        420 * n, gnuplot_output("evidence.png"), n);
  for (std::size_t j = 0; j < n; ++j) {
    const std::size_t c0 = 2 + 5 * j;
    const auto& ax = plots.axes[j];
    script += fmt::format("set title {}\nset xlabel 'commanded speed mm/s'\nset ylabel {}\n",
                          gnuplot_text(fmt::format(
                              "{}: {} against the commanded speed, both directions: measured (grey) and twin (blue); "
                              "friction levels and the constant load show as the two bands",
                              ax.name, ax.channel)),
                          gnuplot_text(ax.unit));
    script += measured_and_twin(d, c0 + 4, c0, c0 + 1, "points pt 7 ps 0.3");
  }
  script += "unset multiplot\n";
  run_gnuplot(results.staging_dir(), script, {"overlay.png", "evidence.png"});
  return {results.path("overlay.png"), results.path("evidence.png")};
}


namespace {
/// The force components of the force calibration's files, in their order.
constexpr std::array<const char*, 3> kForceNames{"fx_N", "fy_N", "fz_N"};
}  // namespace

std::vector<std::filesystem::path> plot_force_calibration(const std::filesystem::path& dir,
                                                          const ForceCalibrationPlots& plots) {
  std::vector<std::string> outputs{"revolution.png"};
  const std::string rev = gnuplot_file(plots.revolution_name);
  std::string g = "set datafile separator ','\nset grid\n";
  const std::size_t nf = std::max<std::size_t>(1, plots.feed_fz_mm.size());
  g += fmt::format("set terminal pngcairo size 1500,{} noenhanced\nset output {}\nset multiplot layout {},3\n",
                   260 * nf, gnuplot_output("revolution.png"), nf);
  for (std::size_t i = 0; i < plots.feed_fz_mm.size(); ++i)
    for (int a = 0; a < 3; ++a)
      g += fmt::format("set title 'feed {} (fz {:.4f} mm): {} over one revolution'\nset xlabel 'spindle angle deg'\n"
                       "set ylabel 'N'\nplot {} index {} every ::1 using 2:{} with points pt 7 ps 0.4 title 'measured', "
                       "'' index {} every ::1 using 2:{} with lines lw 2 title 'model'\n",
                       i, plots.feed_fz_mm[i], kForceNames[a], rev, i, 3 + 2 * a, i, 4 + 2 * a);
  g += "unset multiplot\n";
  if (plots.spectrum) {
    outputs.push_back("residual_spectrum.png");
    g += fmt::format("set terminal pngcairo size 1200,900 noenhanced\nset output {}\nset multiplot layout 3,1\n",
                     gnuplot_output("residual_spectrum.png"));
    for (int a = 0; a < 3; ++a) {
      g += "unset arrow\n";
      for (double f = plots.spindle_Hz; f < plots.spectrum_max_Hz; f += plots.spindle_Hz) {
        const bool tooth = std::abs(std::fmod(f / plots.tooth_Hz + 0.5, 1.0) - 0.5) < 1e-6;
        if (!tooth && f > 5.5 * plots.spindle_Hz) continue;
        g += fmt::format("set arrow from {:.3f}, graph 0 to {:.3f}, graph 1 nohead lc rgb '{}' dt 2\n", f, f,
                         tooth ? "#2060c0" : "#c02020");
      }
      g += fmt::format("set title 'residual spectrum {} (red dashed: spindle harmonics, blue: tooth harmonics)'\n"
                       "set xlabel 'Hz'\nset ylabel 'N'\nset logscale y\nplot {} every ::1 using 1:{} with lines "
                       "title 'before', '' every ::1 using 1:{} with lines title 'after'\nunset logscale y\n",
                       kForceNames[a], gnuplot_file(plots.spectrum_name), 2 + a, 5 + a);
    }
    g += "unset multiplot\n";
  }
  run_gnuplot(dir, g, outputs);
  std::vector<std::filesystem::path> written;
  for (const auto& o : outputs) written.push_back(dir / o);
  return written;
}

std::vector<std::filesystem::path> plot_sweep(io::ResultSet& results, const SweepPlots& plots) {
  if (plots.columns.empty()) return {};
  std::string g = "set datafile separator ','\n"
                  "set terminal pngcairo size 1200,900 font 'DejaVu Sans,11' noenhanced\n"
                  "set grid\nset xlabel 'case'\n"
                  "set output " + gnuplot_output("summary.png") + "\n";
  g += fmt::format("set multiplot layout {},1\n", plots.columns.size());
  for (const auto& c : plots.columns)
    g += "set title " + gnuplot_text(c + " per case (failed cases left out)") + "\nplot " +
         gnuplot_file(plots.results_name) + " using 'case':(column(" + gnuplot_text(c) +
         ")) with linespoints pt 7 lc rgb '#1f77b4' notitle\n";
  g += "unset multiplot\nunset output\n";
  std::vector<std::filesystem::path> written{results.path("summary.png")};
  run_gnuplot(results.staging_dir(), g, {"summary.png"});
  return written;
}

std::vector<std::filesystem::path> plot_lobes(io::ResultSet& results, const LobesPlot& p) {
  // Depths up to the boundary's highest, but at least the scenario's and at
  // most what shows the lowest lobes and the scenario's point well.
  const double a_top =
      std::min(std::max(3.0 * p.lobe_min_mm, 1.5 * p.ap_mm), std::max(p.boundary_max_mm, p.ap_mm));
  const std::string title = fmt::format("{}: zero-order stability lobes, {} teeth, immersion {:.0f}-{:.0f} deg",
                                        p.scenario, p.teeth, p.entry_deg, p.exit_deg);
  const std::string script = fmt::format(
      "set terminal pngcairo size 1100,650 noenhanced\nset output {}\nset datafile separator ','\n"
      "set title {}\nset xlabel 'spindle speed, rev/min'\nset ylabel 'axial depth of cut, mm'\n"
      "set logscale x\nset xrange [{}:{}]\nset yrange [0:{}]\nset grid\nset key top left\n"
      "plot {} skip 1 using 1:2 with lines lw 2 lc rgb '#1f4e99' title 'stability boundary (chatter above)', "
      "'-' using 1:2 with points pt 7 ps 2 lc rgb '{}' title {}\n{},{}\ne\n",
      gnuplot_output("lobes.png"), gnuplot_text(title), p.rpm_min, p.rpm_max, a_top, gnuplot_file(p.boundary_name),
      p.stable ? "#2a9d3a" : "#c0392b",
      gnuplot_text(fmt::format("scenario: {:.0f} rpm, ap {:.3g} mm ({})", p.rpm, p.ap_mm,
                               p.stable ? "stable" : "chatter")),
      p.rpm, p.ap_mm);
  run_gnuplot(results.staging_dir(), script, {"lobes.png"});
  return {results.path("lobes.png")};
}

}  // namespace twin::analysis
