// The coupled twin's chatter onset against the stability lobes (the
// acceptance of the regenerative chip in the co-simulation).
//
// The twin (FADAL 2216 drives and position loops, the milling process on its
// height map, the tool's modes advanced at substep midpoints, the chip
// regenerating against the deflection one or more tooth periods ago) cuts a
// slot at 10 spindle speeds across lobes 0 and 1; at each speed the depth at
// which it starts to chatter is found by bisection on the check mode's verdict
// (twin/structure/chatter_check: the force spectrum's non-harmonic line in the
// modes' band against the tooth harmonics, ringing down or not). The oracle is
// the zero-order lobes (process/stability_lobes, itself checked against the
// closed-form turning limit to 1e-9), computed on their own from the same
// modes and coefficients.
//
// Why 10 %: the zero-order solution averages the directional coefficients
// over a tooth period; for a slot with four teeth (two in the cut at any
// time) the time-varying part is small, and the literature puts the
// zero-order limit within a few per cent of time-domain and
// semi-discretisation limits there (Altintas and Budak 1995; Insperger and
// Stepan 2004). The twin adds what the lobes leave out and moves the onset by
// a few per cent: the drives' motion under the cutting force, the
// height map's cell-scale engagement, the discrete force samples (1.5 deg) and
// the verdict's own resolution (a growth of 20 % in r between two 0.1 s
// windows: about 1 % of depth near the boundary at this damping). 10 % is
// the acceptance and holds those with margin (measured: within 2 % at all ten
// speeds, bisection resolution 0.6 %); a twin whose regeneration were wrong
// (delay, sign, direction) misses it by far more.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "process/stability_lobes.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/structure/chatter_check.hpp"
#include "twin/structure/lobe_study.hpp"

namespace twin::structure {
namespace {

struct SlotCut {
  io::Scenario scenario;
  LobeStudy study;
};

SlotCut slot_setup() {
  SlotCut s{io::load_scenario(io::default_scenario_path(), "fadal2216_structure"), {}};
  io::Scenario& sc = s.scenario;
  sc.machine.tool_tip = {};
  sc.machine.tool_tip.x = {process::ToolTipMode{900.0, 0.04, 8.0e6}};
  sc.machine.tool_tip.y = {process::ToolTipMode{950.0, 0.04, 9.0e6}};
  process::ProcessSetup& ps = *sc.process_setup;
  ps.tool = process::ToolGeometry{};
  ps.tool.name = "flat_d10_z4";
  ps.tool.diameter_mm = 10.0;
  ps.tool.flutes = 4;
  ps.tool.helix_deg = 0.0;
  ps.tool.flute_length_mm = 20.0;
  ps.coefficients = process::CuttingCoefficients::linear(700.0, 210.0, 0.0, 0.0, 0.0, 0.0);
  ps.stock.cell_mm = 0.05;
  ps.options.dz_mm = 0.1;
  LobeStudy& st = s.study;
  st.tool_tip = sc.machine.tool_tip;
  st.cut.immersion = process::Immersion::of_cut(10.0, 10.0, process::MillingMode::kUp, "slot");
  st.cut.fz_mm = 0.05;
  st.cut.feed_angle_deg = 0.0;
  st.settings.teeth = 4;
  st.settings.Ktc_N_per_mm2 = 700.0;
  st.settings.Kr_ratio = 0.3;
  st.settings.immersion = st.cut.immersion;
  st.settings.lobes = 6;
  st.lobes = process::zero_order_lobes(st.tool_tip, st.settings);
  return s;
}

bool chatters(const SlotCut& s, double rpm, double ap) {
  return check_chatter(s.scenario, s.study, ChatterCheckPoint{rpm, ap}).chatter;
}

TEST(ChatterOnset, BisectedOnsetMatchesTheLobesAtTenSpeeds) {
  const SlotCut s = slot_setup();
  for (double rpm : {6000.0, 6800.0, 7600.0, 8400.0, 9200.0, 10000.0, 11000.0, 12000.0, 13000.0, 14000.0}) {
    const double a_lim = s.study.lobes.critical_depth_mm(rpm);
    ASSERT_TRUE(std::isfinite(a_lim)) << rpm;
    double lo = 0.6 * a_lim, hi = 1.4 * a_lim;
    ASSERT_FALSE(chatters(s, rpm, lo)) << rpm << " rpm at " << lo << " mm (lobes " << a_lim << " mm)";
    ASSERT_TRUE(chatters(s, rpm, hi)) << rpm << " rpm at " << hi << " mm (lobes " << a_lim << " mm)";
    for (int i = 0; i < 6; ++i) {
      const double mid = 0.5 * (lo + hi);
      (chatters(s, rpm, mid) ? hi : lo) = mid;
    }
    const double onset = 0.5 * (lo + hi);
    EXPECT_NEAR(onset / a_lim, 1.0, 0.10) << rpm << " rpm: twin onset " << onset << " mm, lobes " << a_lim << " mm";
    std::printf("%6.0f rpm: lobes %.3f mm, twin onset %.3f mm (%+.1f %%)\n", rpm, a_lim, onset,
                100.0 * (onset / a_lim - 1.0));
  }
}

// A cut far inside the stable region rings down; far above the boundary it
// chatters at a frequency near the modes (between them and 1.3 times the
// highest, as the lobes' chatter frequencies are).
TEST(ChatterOnset, StableAndChatteringCutsLookSo) {
  const SlotCut s = slot_setup();
  const double rpm = 9000.0;
  const double a_lim = s.study.lobes.critical_depth_mm(rpm);
  const ChatterCheckResult stable = check_chatter(s.scenario, s.study, {rpm, 0.5 * a_lim});
  EXPECT_FALSE(stable.chatter);
  EXPECT_FALSE(stable.lobe_chatter);
  EXPECT_LT(stable.ratio, stable.ratio_early);
  const ChatterCheckResult loud = check_chatter(s.scenario, s.study, {rpm, 2.0 * a_lim});
  EXPECT_TRUE(loud.chatter);
  EXPECT_TRUE(loud.lobe_chatter);
  EXPECT_GT(loud.chatter_Hz, 900.0);
  EXPECT_LT(loud.chatter_Hz, 1.3 * 950.0);
  EXPECT_GT(loud.max_deflection_um, 5.0 * stable.max_deflection_um);
}

}  // namespace
}  // namespace twin::structure
