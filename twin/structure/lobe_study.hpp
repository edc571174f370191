#pragma once
/// `twin lobes`: the zero-order stability lobes of a scenario's cut, from the
/// machine's tool-tip modes and the process's cutting coefficients, with the
/// scenario's own speed and depth marked.
#include <string>
#include <vector>

#include "process/stability_lobes.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/structure/cut_study.hpp"

namespace twin::structure {

struct LobeStudyOptions {
  int lobes{10};          ///< at least this many; more where the scenario's speed needs them (up to 400)
  double rpm_min{0.0};    ///< plotted speed range; 0: from the lobes themselves
  double rpm_max{0.0};
  int boundary_points{600};
  void validate() const;
};

struct ChatterCheckPoint {
  double spindle_rpm{0.0};
  double ap_mm{0.0};
  /// "RPM:DEPTH_mm"; throws ConfigError naming the text when malformed or out of range.
  static ChatterCheckPoint parse(const std::string& text);
};

struct ChatterCheckResult {
  ChatterCheckPoint point;
  double a_crit_mm{0.0};          ///< the lobes' critical depth at the speed (inf: none covers it)
  bool lobe_chatter{false};       ///< ap >= a_crit
  bool chatter{false};            ///< the twin's verdict
  double ratio_early{0.0};        ///< r in window 2
  double ratio{0.0};              ///< r in window 3
  double chatter_Hz{0.0};         ///< the largest non-harmonic line in window 3
  double tooth_Hz{0.0};
  double max_deflection_um{0.0};  ///< |tool deflection| in window 3
  double simulated_s{0.0};
};

struct LobeStudy {
  std::string scenario;
  std::string machine;
  std::string tool_tip_source;
  process::ToolTipFrf tool_tip;
  CutCondition cut;                      ///< the scenario's longest cut
  std::size_t cut_conditions{0};         ///< distinct cuts found in the program
  LinearisedCoefficients coefficients;
  process::LobeSettings settings;
  process::StabilityLobes lobes;
  double rpm{0.0};                       ///< |spindle speed| of the cut
  double a_crit_mm{0.0};                 ///< the lobes' critical depth at rpm (inf: no lobe covers it)
  double chatter_Hz{0.0};                ///< chatter frequency of the boundary at rpm
  bool stable{true};                     ///< ap below a_crit
  double rpm_min{0.0}, rpm_max{0.0};     ///< range of the boundary table
  std::vector<std::array<double, 3>> boundary;   ///< rpm, a_crit_mm, chatter_Hz
  std::vector<ChatterCheckResult> checks;         ///< the check mode's points (twin/structure/chatter_check)
};

/// Throws ConfigError when the scenario has no process, the machine no tool-tip
/// modes, or the program never cuts.
LobeStudy study_lobes(const io::Scenario& scenario, const LobeStudyOptions& options);

/// lobes.csv (every lobe point), boundary.csv (the stability boundary over
/// speed), report.json and lobes.png; returns the staged paths written.
std::vector<std::filesystem::path> write_lobe_study(io::ResultSet& results, const LobeStudy& study);

/// One line: speed, depth, critical depth, verdict.
std::string lobe_summary(const LobeStudy& study);

}  // namespace twin::structure
