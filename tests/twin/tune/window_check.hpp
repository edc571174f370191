#pragma once
// The check the tuning tests share: the steady-motion window around a
// scenario's corner reproduces the full run through it.
#include <gtest/gtest.h>

#include "twin/io/scenario_file.hpp"
#include "twin/tune/tune.hpp"

namespace twin::analysis::testing {

/// `full` and `win` := the scenario simulated whole and over the window from
/// 30 ms before its corner to 30 ms after; both complete, the window in fewer
/// ticks, their max contour errors within 1 um (one encoder count, the
/// quantisation of the error the loop acts on).
inline void expect_corner_window_matches_full_run(const io::Scenario& sc, ScenarioMetrics& full, ScenarioMetrics& win) {
  const PlannedScenario planned = plan_scenario(sc);
  full = simulate_window(sc, planned, sc.machine, full_window(planned));
  win = simulate_window(sc, planned, sc.machine, corner_window(planned, 0.03, 0.03));
  ASSERT_TRUE(full.completed && win.completed);
  EXPECT_LT(win.ticks, full.ticks);
  EXPECT_NEAR(win.max_contour_error_mm, full.max_contour_error_mm, 1e-3);
}

}  // namespace twin::analysis::testing
