#pragma once
/// The check mode of `twin lobes`: the coupled twin (drives, position loops,
/// the milling process with the tool's modes and the regenerative chip) runs a
/// straight cut at a chosen spindle speed and depth, at the scenario's
/// immersion, feed per tooth and feed direction, and says from the force's
/// spectrum whether it chatters; beside it, the lobes' verdict at that point.
///
/// The cut: a block whose edge leaves the scenario's radial depth (up milling:
/// material on the left of the feed, phi from 0; down milling: on the right,
/// phi to 180 deg; a slot: both), already cut up to the start, the tool at the
/// start in the cut at rest and the reference moving along the feed at the
/// programmed feed from the first tick. The run lasts three windows of
/// L = max(0.1 s, 16 tooth periods).
///
/// The verdict (process/chatter_spectrum.hpp): the tick-averaged force on the
/// workpiece in x and y (what the drives see) in windows 2 and 3, r_2 and r_3
/// between half the lowest and 1.5 times the highest tool mode;
/// chatter_verdict(r_2, r_3).
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "twin/io/atomic_file.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/structure/lobe_study.hpp"

namespace twin::structure {

/// Runs the coupled twin at one point. `study` gives the cut (immersion, feed
/// per tooth, direction) and its lobes (recomputed with more lobe numbers when
/// the speed is below the ones computed). Throws ConfigError for a scenario
/// without process or tool modes, or a point out of range.
ChatterCheckResult check_chatter(const io::Scenario& scenario, const LobeStudy& study, const ChatterCheckPoint& point);

/// check.csv, one row per point (written by write_lobe_study when the study has checks).
std::string chatter_checks_csv(const std::vector<ChatterCheckResult>& checks);

/// The points as report.json's "check" array.
nlohmann::json chatter_checks_json(const std::vector<ChatterCheckResult>& checks);

/// One line per point.
std::string chatter_check_summary(const ChatterCheckResult& r);

}  // namespace twin::structure
