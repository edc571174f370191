#include "twin/analysis/plots.hpp"

#include <array>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <sys/wait.h>

#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"

namespace twin::analysis {

std::string gnuplot_quote(const std::filesystem::path& p) {
  std::string s = "'";
  for (char c : p.string()) {
    if (c == '\'') s += "''";
    else s += c;
  }
  return s + "'";
}

void run_gnuplot(const std::filesystem::path& work_dir, const std::string& script,
                 const std::vector<std::filesystem::path>& outputs) {
  // Outputs are written as <name>.tmp.png and renamed after gnuplot succeeds.
  const auto script_path = work_dir / ".plots.gp.tmp";
  {
    std::ofstream f(script_path);
    f << script;
    if (!f) throw IoError(fmt::format("cannot write {}", script_path.string()));
  }
  const auto log_path = work_dir / ".plots.log.tmp";
  auto shell_quote = [](const std::filesystem::path& p) {
    std::string q = "'";
    for (char c : p.string()) q += (c == '\'') ? std::string("'\\''") : std::string(1, c);
    return q + "'";
  };
  const std::string cmd = fmt::format("gnuplot {} > {} 2>&1", shell_quote(script_path), shell_quote(log_path));
  const int rc = std::system(cmd.c_str());
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
  std::error_code ec;
  std::filesystem::remove(script_path, ec);
  std::filesystem::remove(log_path, ec);
  const bool ok = rc != -1 && WIFEXITED(rc) && WEXITSTATUS(rc) == 0;
  for (const auto& o : outputs) {
    auto tmp = o;
    tmp += ".tmp.png";
    if (!ok || !std::filesystem::exists(tmp)) {
      for (const auto& p : outputs) {
        auto t = p;
        t += ".tmp.png";
        std::filesystem::remove(t, ec);
      }
      throw IoError(fmt::format("gnuplot could not draw {}: {}", o.filename().string(),
                                first_error.empty() ? (ok ? "no output" : "gnuplot failed or is not installed")
                                                    : first_error));
    }
  }
  for (const auto& o : outputs) {
    auto tmp = o;
    tmp += ".tmp.png";
    std::filesystem::rename(tmp, o, ec);
    if (ec) throw IoError(fmt::format("cannot rename {}: {}", tmp.string(), ec.message()));
  }
}

std::vector<std::filesystem::path> plot_run(const std::filesystem::path& out_dir, const std::filesystem::path& trace,
                                            const std::vector<Axis>& axes, const std::vector<CornerWindow>& corners,
                                            bool cutting) {
  std::vector<std::filesystem::path> outputs{out_dir / "feedrate.png", out_dir / "errors.png"};
  if (cutting) outputs.push_back(out_dir / "forces.png");
  const std::string T = gnuplot_quote(trace);
  std::ostringstream g;
  g << "set datafile separator ','\n"
    << "set terminal pngcairo size 1400,1000 font 'DejaVu Sans,11' noenhanced\n"
    << "set key outside top center horizontal\n"
    << "set grid\n"
    << "set xlabel 'time [s]'\n";
  std::ostringstream marks;
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const double t = corners[c].corner.t_s;
    marks << fmt::format("set arrow {} from {:.6f}, graph 0 to {:.6f}, graph 1 nohead dt 2 lc rgb '#888888'\n", c + 1,
                         t, t);
    marks << fmt::format("set label {} 'corner {}: {:.0f} deg, line {}' at {:.6f}, graph 0.97 rotate by 90 right "
                         "font ',9'\n",
                         c + 1, c + 1, corners[c].corner.turn_angle_deg, corners[c].line_after, t);
  }
  // Thin the full view to about 20000 points a curve; the corner zoom uses every sample.
  g << "stats " << T << " using 1 nooutput\n"
    << "every_n = (STATS_records > 20000) ? int(STATS_records / 20000) : 1\n"
    << marks.str();
  auto tmp = [](const std::filesystem::path& p) {
    auto t = p;
    t += ".tmp.png";
    return gnuplot_quote(t);
  };
  // Each figure: the whole run on top and, when the program has corners, the
  // first corner's window below (+-0.25 s or the window, whichever is wider).
  std::string zoom;
  if (!corners.empty()) {
    const auto& c = corners.front();
    const double t0 = std::min(c.corner.t_s - 0.25, c.t_begin_s - 0.05);
    const double t1 = std::max(c.corner.t_s + 0.25, c.t_end_s + 0.05);
    zoom = fmt::format("set xrange [{:.6f}:{:.6f}]\n", t0, t1);
  }
  auto figure = [&](const std::filesystem::path& out, const std::string& title, const std::string& setup,
                    const std::string& plot_full, const std::string& plot_zoom) {
    g << "set output " << tmp(out) << "\n";
    if (!zoom.empty()) g << "set multiplot layout 2,1\n";
    g << setup << "set title '" << title << "'\nset autoscale x\n" << plot_full << "\n";
    if (!zoom.empty())
      g << "set title '" << title << ", around corner 1'\n" << zoom << plot_zoom << "\nunset multiplot\n";
    g << "set autoscale x\nunset y2tics\nunset y2label\nset ytics mirror\n";
  };
  auto feed_plot = [&](const std::string& every) {
    return "plot " + T + every +
           " using 't_s':'feed_programmed_mm_per_min' with lines lw 2 lc rgb '#999999' title 'programmed', '' " +
           every + " using 't_s':'feed_ref_mm_per_min' with lines lw 2 lc rgb '#1f77b4' title 'interpolator "
           "reference', '' " + every + " using 't_s':'feed_mm_per_min' with lines lw 1 lc rgb '#d62728' title "
           "'real (drives)'";
  };
  figure(outputs[0], "Feedrate (dashed lines: corners)", "set ylabel 'feed [mm/min]'\n", feed_plot(" every every_n"),
         feed_plot(""));
  const std::array<const char*, 3> colours{"#1f77b4", "#2ca02c", "#9467bd"};
  auto error_plot = [&](const std::string& every) {
    std::string p = "plot ";
    for (std::size_t i = 0; i < axes.size(); ++i) {
      const std::string n(axis_name(axes[i]));
      p += (i ? ", " : "") + T + every + " using 't_s':(column('" + n + "_err_mm')*1000) with lines lc rgb '" +
           colours[i % 3] + "' title '" + n + " tracking error'";
    }
    return p + ", ''" + every +
           " using 't_s':(column('contour_error_mm')*1000) with lines lw 2 lc rgb '#d62728' title 'contour error'";
  };
  figure(outputs[1], "Tracking error per axis and contour error", "set ylabel 'error [um]'\n",
         error_plot(" every every_n"), error_plot(""));
  if (cutting) {
    auto force_plot = [&](const std::string& every) {
      return "plot " + T + every + " using 't_s':'fx_avg_N' with lines lc rgb '#1f77b4' title 'fx (tick mean)', ''" +
             every + " using 't_s':'fy_avg_N' with lines lc rgb '#2ca02c' title 'fy (tick mean)', ''" + every +
             " using 't_s':'fz_avg_N' with lines lc rgb '#9467bd' title 'fz (tick mean)', ''" + every +
             " using 't_s':'engagement_deg' axes x1y2 with lines lc rgb '#ff7f0e' title 'engagement'";
    };
    figure(outputs[2], "Cutting force on the workpiece and engagement",
           "set ylabel 'force [N]'\nset y2label 'engagement [deg]'\nset y2tics\nset ytics nomirror\n",
           force_plot(" every every_n"), force_plot(""));
  }
  g << "unset output\n";
  run_gnuplot(out_dir, g.str(), outputs);
  return outputs;
}

}  // namespace twin::analysis
