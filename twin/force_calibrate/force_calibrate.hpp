#pragma once
/// `twin calibrate` on dynamometer force logs (spec/measured-data.md, "Force
/// logs"): cutting coefficients, runout and the effects the force model lacks.
///
/// A force run is a folder with trace.csv(.gz) (t_s, fx_N, fy_N, fz_N, and
/// optionally spindle_deg) and a meta.json whose `cut` object says what was
/// cut; a series is a folder of such runs (one tool, several feeds, in the
/// order they were cut: sorted by folder name).
///
/// The model of a logged force (machine axes, on the workpiece):
///   F_logged(t) = s(t) * [H * F_cut](phi(t)) + o + d t + noise
/// with F_cut the mechanistic model of docs/force-calibration.md (axial
/// slices, helix, runout chip of Kline-DeVor, linear or exponential
/// coefficients), H a delay (the anti-alias filter) and, as an effect, a
/// second-order sensor mode, s(t) = 1 + w (L(t) - L_ref) a wear law in the
/// cut length L, o and d the dynamometer's zero offset and drift.
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace twin::analysis::force {

/// The `cut` object of meta.json.
struct ForceCut {
  double diameter_mm{0.0};
  int flutes{0};
  double helix_deg{0.0};
  double corner_radius_mm{0.0};
  double spindle_rpm{0.0};
  double feed_mm_per_min{0.0};
  double feed_direction_deg{0.0};
  double ae_mm{0.0};
  double ap_mm{0.0};
  std::string milling;     ///< slot, up, down
  std::string material;
  double feed_per_tooth_mm() const { return feed_mm_per_min / (flutes * spindle_rpm); }
  /// Engaged immersion [start, exit] (rad, phi clockwise from the feed frame's +y).
  std::array<double, 2> immersion_rad() const;
};

/// One force run as read.
struct ForceRun {
  std::string name;                      ///< folder name
  std::filesystem::path dir;
  ForceCut cut;
  double sample_period_s{0.0};
  std::vector<double> t_s;
  std::array<std::vector<double>, 3> F_N;   ///< fx, fy, fz (fz may be empty: not logged)
  std::vector<double> spindle_deg;          ///< empty when not logged
};

/// True when `path` holds a meta.json with a `cut` object, or sub-folders that do.
bool is_force_data(const std::filesystem::path& path);
/// Reads one run; ConfigError/IoError "<file>: cut.<field> ..." on a missing or bad field.
ForceRun load_force_run(const std::filesystem::path& dir);
/// A run folder, or a folder of run folders (sorted by name). The runs must
/// share the tool. Throws naming the folder when none holds a force run.
std::vector<ForceRun> load_force_series(const std::filesystem::path& path);

/// Runout of the tool: R_j(z) = R + rho cos(lambda - j 2pi/N + z tan(beta)/R).
struct Runout {
  double rho_mm{0.0};
  double lambda_deg{0.0};
};

/// A sensor mode H(s) = wn^2/(s^2 + 2 zeta wn s + wn^2) in the force output.
struct SensorMode {
  double f_hz{0.0};
  double zeta{0.0};
};

/// K(h) = a + b exp(-c h) per direction (b = 0: linear) and edge coefficients.
struct ForceCoefficients {
  std::array<double, 3> a{};   ///< Ktc, Krc, Kac (N/mm^2)
  std::array<double, 3> b{};   ///< exponential part (N/mm^2)
  double c_per_mm{0.0};        ///< shared decay (1/mm)
  std::array<double, 3> e{};   ///< Kte, Kre, Kae (N/mm)
  bool exponential{false};
};

/// The whole identified model.
struct ForceModel {
  ForceCoefficients k;
  std::array<double, 6> k_stderr{};   ///< standard errors of Ktc..Kae (linear fit)
  Runout runout;
  std::optional<SensorMode> mode;
  double delay_s{0.0};                ///< the logged force lags the spindle angle by this (filters)
  double lowpass_hz{0.0};             ///< the log's anti-alias filter, 2nd-order Butterworth (0: none)
  double wear_per_mm{0.0};            ///< w: coefficients scale with 1 + w (L - L_ref)
  double wear_L_ref_mm{0.0};
  std::vector<double> phi0_deg;       ///< per run, where spindle_deg is not logged
};

/// Zero offset and drift of one run, and its windows.
struct RunZero {
  std::array<double, 3> offset_N{};       ///< o of F_logged = F + o + d t
  std::array<double, 3> drift_N_per_s{};
  std::string drift_source;               ///< "air before and after" or "fitted over the cut"
  double t_entry_s{0.0};
  double t_exit_s{0.0};
  double t_steady_begin_s{0.0};
  double t_steady_end_s{0.0};
  int revolutions{0};
  double noise_N{0.0};
};

struct EffectAdded {
  std::string effect;
  nlohmann::json params;
  std::string evidence;
};

struct FeedResult {
  std::string run;
  double fz_mm{0.0};
  std::array<double, 3> mean_measured_N{};
  std::array<double, 3> mean_model_N{};
  std::array<double, 3> p2p_measured_N{};
  std::array<double, 3> p2p_model_N{};
  ForceCoefficients exponential;          ///< Duan's K(h) from this feed alone
  std::array<double, 3> spindle_line_measured_N{};   ///< amplitude at the spindle frequency
  std::array<double, 3> spindle_line_model_N{};
  std::vector<double> rev_theta_deg;      ///< one revolution: measured (synchronous average) and model
  std::array<std::vector<double>, 3> rev_measured_N;
  std::array<std::vector<double>, 3> rev_model_N;
};

struct ForceCalibration {
  std::vector<std::string> runs;
  std::string material;                   ///< cut.material of the first run
  ForceModel before;                      ///< linear coefficients (+ delay), no effect
  ForceModel after;                       ///< with the effects added
  ForceCoefficients average_force;        ///< Altintas' average-force regression
  std::array<double, 6> average_force_stderr{};
  ForceCoefficients exponential_joint;    ///< Duan's K(h) over all feeds
  std::vector<RunZero> zero;
  std::vector<EffectAdded> added;
  std::vector<nlohmann::json> candidates; ///< every effect tried, with its held-out errors
  std::array<double, 3> error_before{};   ///< held-out revolutions, rms(F - model)/rms(F)
  std::array<double, 3> error_after{};
  std::array<double, 3> noise_floor{};    ///< the same ratio for the noise alone
  nlohmann::json held_out_feed;           ///< fit without one feed, that feed predicted
  std::vector<FeedResult> feeds;
  std::string validation;
  std::vector<std::string> notes;
  double spindle_hz{0.0};
  double tooth_hz{0.0};
  std::vector<double> spectrum_f_hz;      ///< residual amplitude spectrum (mean over runs), before and after
  std::array<std::vector<double>, 3> spectrum_before_N;
  std::array<std::vector<double>, 3> spectrum_after_N;
};

struct ForceCalibrationOptions {
  int slices{50};               ///< axial slices over ap
  int grid{720};                ///< angle grid per revolution for the harmonics
  bool held_out_feed{true};     ///< also fit without one feed and predict it
};

ForceCalibration calibrate_forces(const std::vector<ForceRun>& runs, const ForceCalibrationOptions& options = {});

nlohmann::json force_report_json(const ForceCalibration& r);
std::string force_report_markdown(const ForceCalibration& r, const std::string& source);
/// Files `twin cut` and `twin run` load as they are (twin/io/process_yaml).
std::string material_yaml(const ForceCalibration& r, const std::string& source);
std::string tool_yaml(const ForceCalibration& r, const ForceCut& cut, const std::string& source);

/// `twin calibrate SERIES -o OUT` on force data: reads, identifies, writes
/// report.json, report.md, material.yaml, tool.yaml and (unless no_plots)
/// the plots. Prints one summary line.
void run_force_calibration(const std::filesystem::path& series, const std::filesystem::path& out, bool no_plots);

}  // namespace twin::analysis::force
