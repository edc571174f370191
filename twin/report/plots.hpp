#pragma once
/// Plots a person looks at, drawn by gnuplot (Debian's gnuplot-nox): PNG files
/// in a command's result set.
///
/// The one way the project drives gnuplot. No string from input (folder, run,
/// scenario or machine names) reaches gnuplot or a shell as code:
///  - gnuplot is started by fork and exec with a fixed argument vector (no
///    shell), in the folder that holds the data and receives the plots;
///  - scripts name files only by plain names the program chose
///    (gnuplot_file: letters, digits, '_', '-', '.'), never by a path;
///  - any other text (titles) goes through gnuplot_text: a single-quoted
///    literal, in which gnuplot expands nothing (no backquote or macro
///    substitution), with a quote doubled and every byte outside printable
///    ASCII (newline included) replaced by '?', so the literal cannot end early.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "twin/report/run_report.hpp"
#include "twin/io/atomic_file.hpp"

namespace twin::analysis {

/// A file of gnuplot's working folder as a gnuplot string literal.
/// InternalError for anything but a plain name of [A-Za-z0-9_.-] not starting with '.'.
std::string gnuplot_file(std::string_view name);
/// Text (a title or label) as a safe single-quoted gnuplot literal (see above).
std::string gnuplot_text(std::string_view text);
/// The temporary name gnuplot writes the plot `final_name` to (a gnuplot_file
/// literal of "<final_name>.tmp.png"); run_gnuplot renames it.
std::string gnuplot_output(std::string_view final_name);

/// Runs gnuplot on `script` in `work_dir`. Each of `outputs` (plain names in
/// work_dir) must have been written by the script to gnuplot_output(name) and is
/// renamed to its name when gnuplot succeeds. Temporaries (script, log, partial
/// plots) are removed, also when the process is ended by a signal. Throws
/// IoError with gnuplot's first error line otherwise.
void run_gnuplot(const std::filesystem::path& work_dir, const std::string& script,
                 const std::vector<std::string>& outputs);

/// feedrate.png (programmed, reference and real feed over time, corners
/// marked), errors.png (tracking per axis and contour error), and with a cut
/// forces.png (fx fy fz and engagement), drawn from the result set's file
/// `trace_name` (`rows` data rows). With the plan (`trajectory`), a corner and the x and y axes,
/// also corner_path.png: the XY path at the first corner (programmed
/// corner, planned blend arc, reference and the drives' real path coloured
/// by the force) and the force and engagement along the path. Returns the
/// plots written (staged paths of `results`).
std::vector<std::filesystem::path> plot_run(io::ResultSet& results, const std::string& trace_name,
                                            std::size_t rows, const std::vector<Axis>& axes,
                                            const std::vector<CornerWindow>& corners, bool cutting,
                                            const controller::Trajectory* trajectory = nullptr);

/// The effect `twin calibrate` added first, for evidence.png.
struct CalibrationEvidence {
  std::string effect;        ///< e.g. "cogging"
  Axis axis{Axis::kX};
  std::size_t axis_slot{0};  ///< position of the axis in the residual file's axes
  bool over_position{false}; ///< plotted over the axis position (else over time)
};

/// residual_before.png, residual_after.png (tracking error and low-passed u,
/// measured minus model, per axis) and with `evidence` evidence.png, from the
/// result set's file `residuals_name`: columns t_s, then per axis <a>_mm,
/// <a>_err_res_before_mm, <a>_err_res_after_mm, <a>_u_res_before, <a>_u_res_after.
/// Returns the plots written (staged paths of `results`).
std::vector<std::filesystem::path> plot_calibration(io::ResultSet& results, const std::string& residuals_name,
                                                    const std::vector<Axis>& axes,
                                                    const std::optional<CalibrationEvidence>& evidence);

/// What twin tune's plots draw: `bode_name` (per axis of `axes`, the loop before
/// and after tuning, one gnuplot index each: f_Hz, |L|_dB, arg L in deg, |S|_dB, ...)
/// and, with a `corner_title`, `corner_name` (t_s, per axis the error before and
/// after in um, then the contour error before and after), both in the result set.
struct TunePlots {
  std::string machine_name;
  std::vector<Axis> axes;
  std::string bode_name{"bode.dat"};
  std::string corner_name{"corner_error.dat"};
  std::string corner_title;  ///< empty: no corner_error.png
};

/// What the plots of a machine identified from data draw, from `overlay_name` in
/// the result set: columns t_s, then per axis its torque channel measured and
/// modelled, its following error measured and modelled (mm) and the commanded speed.
struct DataCalibrationPlots {
  struct Axis {
    std::string name;     ///< "x"
    std::string channel;  ///< the torque channel's column
    std::string unit;     ///< its unit as the plot says it
  };
  std::string overlay_name{"overlay.csv"};
  double t_split_s{0.0};  ///< fitted before it, held out after it
  std::vector<Axis> axes;
};

/// overlay.png (per axis the channel and the following error, measured and twin,
/// over time, the fitting part marked) and evidence.png (the channel against the
/// commanded speed). Returns the plots written (staged paths of `results`).
std::vector<std::filesystem::path> plot_data_calibration(io::ResultSet& results, const DataCalibrationPlots& plots);

/// bode.png (|L| and |S|, then arg L) and with a corner corner_error.png (tracking
/// and contour error through it). Returns the plots written (staged paths of `results`).
std::vector<std::filesystem::path> plot_tuning(io::ResultSet& results, const TunePlots& plots);

/// What `twin calibrate`'s force figures draw, from two files in the folder:
/// `revolution_name` (one gnuplot index per feed: feed, theta_deg, then fx, fy
/// and fz measured and model in N) and `spectrum_name` (f_hz, then fx, fy and
/// fz before, then after, in N).
struct ForceCalibrationPlots {
  std::string revolution_name{"revolution.csv"};
  std::vector<double> feed_fz_mm;  ///< the feed per tooth of each index of the revolution file
  std::string spectrum_name{"residual_spectrum.csv"};
  bool spectrum{false};            ///< the spectrum file is there: residual_spectrum.png
  double spectrum_max_Hz{0.0};     ///< the spectrum's last frequency
  double spindle_Hz{0.0};          ///< harmonics of the spindle marked (red) ...
  double tooth_Hz{0.0};            ///< ... and of the tooth passing (blue)
};

/// revolution.png (per feed and force component, measured and model over one
/// revolution) and with a spectrum residual_spectrum.png (before and after, the
/// harmonics marked), drawn in `dir` (not a result set: the force calibration
/// writes its files in place). Returns the paths written.
std::vector<std::filesystem::path> plot_force_calibration(const std::filesystem::path& dir,
                                                          const ForceCalibrationPlots& plots);

/// What `twin sweep`'s figure draws: `columns` (one or two) of `results_name`
/// in the result set, per case.
struct SweepPlots {
  std::string results_name{"results.csv"};
  std::vector<std::string> columns;  ///< empty: nothing to draw
};

/// summary.png: each column per case, failed cases left out. Returns the plots
/// written (staged paths of `results`; none without columns).
std::vector<std::filesystem::path> plot_sweep(io::ResultSet& results, const SweepPlots& plots);

/// What `twin lobes`' figure draws: the stability boundary from `boundary_name`
/// in the result set (a header, then spindle_rpm, a_crit_mm) and the
/// scenario's own speed and depth.
struct LobesPlot {
  std::string boundary_name{"boundary.csv"};
  std::string scenario;
  int teeth{0};
  double entry_deg{0.0}, exit_deg{0.0};  ///< the cut's immersion
  double rpm_min{0.0}, rpm_max{0.0};     ///< the speed axis
  double boundary_max_mm{0.0};           ///< the boundary's highest finite depth (0: none)
  double lobe_min_mm{0.0};               ///< the lowest depth of any lobe
  double rpm{0.0}, ap_mm{0.0};           ///< the scenario's cut
  bool stable{true};
};

/// lobes.png: the boundary over speed (log) with the scenario's point, green
/// when stable, red when it chatters. Returns the plots written (staged paths of `results`).
std::vector<std::filesystem::path> plot_lobes(io::ResultSet& results, const LobesPlot& plot);

}  // namespace twin::analysis
