// Calibration of a machine the twin does not know, from logs shaped like real
// CNCs' (spec/measured-data.md, "Position loops of real machines"):
// - the data checks against closed forms (rounding, stitched segments, the
//   staircase of a rounded ramp rebuilt within half a sample of motion);
// - identification against the truth simulator of these tests (written apart
//   from the twin), run with the cascade law and logged as a real CNC logs:
//   no machine named, torque in an unstated unit, positions rounded.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "truth_sim.hpp"
#include "twin/calibrate/machine_from_data.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"

namespace twin::analysis {
namespace {

using ::testing::HasSubstr;

std::filesystem::path work(const std::string& name) {
  const auto d = std::filesystem::temp_directory_path() / "twin_real_logs_test" / name;
  std::filesystem::remove_all(d);
  std::filesystem::create_directories(d);
  return d;
}

/// Whether one of the calibration's notes says `text`.
bool has_note(const DataCalibration& r, const std::string& text) {
  return std::any_of(r.notes.begin(), r.notes.end(),
                     [&](const std::string& n) { return n.find(text) != std::string::npos; });
}

/// A copy of the run in `from` under `name` (meta.json as it is), with
/// trace.csv rewritten line by line: `edit(row, line)` sees the header as row
/// -1 and the samples from 0, may change the line, and says whether to keep it.
MeasuredRun rewritten_run(const std::filesystem::path& from, const std::string& name,
                          const std::function<bool(std::ptrdiff_t, std::string&)>& edit) {
  const auto d = work(name);
  std::filesystem::copy_file(from / "meta.json", d / "meta.json");
  std::ifstream in(from / "trace.csv");
  std::ofstream out(d / "trace.csv");
  std::string line;
  for (std::ptrdiff_t row = -1; std::getline(in, line); ++row)
    if (edit(row, line)) out << line << "\n";
  out.close();
  return load_run(d);
}

/// The held-out machine's check on the one validation run (another program,
/// never fitted): the following error within 1 % NRMS, and the torque better
/// than the rigid-body regression fitted on the same rows.
void expect_held_out_check(const DataCalibration& r) {
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const auto& e = r.validation_runs[0].calibrated.nrms;
  ASSERT_TRUE(e.count("x_err_mm"));
  EXPECT_LT(e.at("x_err_mm"), 0.01);
  ASSERT_TRUE(e.count("x_torque_raw"));
  EXPECT_LT(e.at("x_torque_raw"), r.validation_runs[0].regression.nrms.at("x_torque_raw"));
}

/// The held-out check on the truth with a current loop that lags, behind
/// `delay_ticks` of dead time. With a dead time the loop is the least
/// damped, and its following error the most sensitive to the drive's
/// friction levels, which the fit through its hunting at low speed takes 3 %
/// off (B 5 % low): the other program tracks at 0.014, torque 0.18 (0.036
/// and 0.46 with the dead time read as 3 ms; on the sweep's run 0.0125, and
/// 0.0086 with the truth's levels). Held at 0.02 there, and the torque below
/// the regression's.
void expect_held_out_check_behind(const DataCalibration& r, int delay_ticks) {
  if (delay_ticks == 0) {
    expect_held_out_check(r);
    return;
  }
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const auto& e = r.validation_runs[0].calibrated.nrms;
  EXPECT_LT(e.at("x_err_mm"), 0.02);
  EXPECT_LT(e.at("x_torque_raw"), r.validation_runs[0].regression.nrms.at("x_torque_raw"));
}

/// A delay of `delay_s` kept (to 1e-9 s: whole loop periods), or none where
/// it is 0.
void expect_delay_kept(const DataCalibration& r, double delay_s) {
  const auto delay = std::find_if(r.effects.begin(), r.effects.end(),
                                  [](const DataEffect& e) { return e.kept && e.effect == "delay"; });
  if (delay_s == 0.0) {
    EXPECT_EQ(delay, r.effects.end());
  } else {
    ASSERT_NE(delay, r.effects.end());
    EXPECT_NEAR(delay->params.at("delay_s"), delay_s, 1e-9);
  }
}

/// The truth's cascade gains (cascade_run_spec: Kv 45 1/s, kff 0.6, Kvp
/// 0.5 N m s/rad times the raw unit's 40 per N m over rg, Tn 8 ms) where the
/// log shows both loops: Kv and kff to 1 % (a regression on the logged loop
/// signals, exact but for the log's rounding and the encoder's 0.5 um), Kvp
/// to 5 % and Tn to 10 %. Where the law was polished on the replay (a log
/// slower than 5 ms), those hold for the law as read, and the polished
/// gains are held to 16 % and 15 %: the polish fits the loop to the drive as
/// identified, and on the truth's Stribeck rise, which that drive or the
/// twin's Stribeck law does not match exactly, it moved Kvp up by 9 to 15 %
/// (the other program's torque NRMS 0.10 to 0.15 with it, against 0.14 to
/// 0.18 without the polish).
void expect_truth_gains(const AxisFromData& ax, const truth::RunSpec& sp) {
  EXPECT_NEAR(ax.gains.Kv_per_s, 45.0, 0.45);
  EXPECT_NEAR(ax.gains.kff, 0.6, 0.01);
  EXPECT_TRUE(ax.velocity_loop_from_data) << ax.loop_source;
  const double Kvp = 0.5 / sp.plant.rg * 40.0;
  const controller::CascadeGains& read = ax.law_before_polish ? *ax.law_before_polish : ax.gains;
  EXPECT_NEAR(read.Kvp_torque_s_per_rad, Kvp, 0.05 * Kvp) << ax.loop_source;
  EXPECT_NEAR(read.Tn_s, 0.008, 0.0008) << ax.loop_source;
  if (ax.law_before_polish) {
    EXPECT_NEAR(ax.gains.Kvp_torque_s_per_rad, Kvp, 0.16 * Kvp) << ax.loop_source;
    EXPECT_NEAR(ax.gains.Tn_s, 0.008, 0.0012) << ax.loop_source;
  }
}

MeasuredRun run_from_csv(const std::string& name, const std::string& csv) {
  const auto d = work(name);
  std::ofstream(d / "meta.json") << R"({"machine": null, "axes": ["x"], "sample_period_s": 0.1})";
  std::ofstream(d / "trace.csv") << csv;
  return load_run(d);
}

// A ramp at 0.37 mm/s sampled every 0.1 s and rounded to 0.1 mm: the
// rounding error is uniform over +-0.05 mm; the crossings of the rounding
// boundaries lie on the true line within half a sample of motion (0.0185 mm),
// and so does the line through them.
TEST(RealLogs, RoundedRampIsRebuiltWithinHalfASampleOfMotion) {
  std::vector<double> t, r, truth;
  for (int k = 0; k < 200; ++k) {
    t.push_back(0.1 * k);
    truth.push_back(1.0 + 0.37 * 0.1 * k);
    r.push_back(std::round(truth.back() * 10.0) / 10.0);
  }
  PositionRounding q;
  q.kind = PositionRounding::Kind::kDecimals;
  q.digits = 1;
  q.quantum_mm = 0.1;
  const std::vector<double> d = dequantize_reference(t, r, q);
  double worst_raw = 0.0, worst = 0.0;
  for (std::size_t k = 10; k + 10 < t.size(); ++k) {
    worst_raw = std::max(worst_raw, std::abs(r[k] - truth[k]));
    worst = std::max(worst, std::abs(d[k] - truth[k]));
  }
  EXPECT_GT(worst_raw, 0.045);
  EXPECT_LT(worst, 0.5 * 0.037 + 1e-9);
}

PositionRounding whole_millimetres() {
  PositionRounding q;
  q.kind = PositionRounding::Kind::kDecimals;
  q.digits = 0;
  q.quantum_mm = 1.0;
  return q;
}

// A segment of 1 s cut by a stitch from a slow diagonal move: the axis runs
// at -0.8 mm/s from 141.7 mm, logged every 0.1 s to whole millimetres (142
// for three rows, 141 for seven). The line is the truth. Rebuilt flat at
// the segment's ends, the axis steps 1 mm within one sample and stands
// still for the other nine; carried on from the crossing at a speed the
// held values allow, it moves the truth's way at every row, and stays
// within the rounding's half quantum of the truth.
TEST(RealLogs, ASlowMoveCutByAStitchIsRebuiltMovingToItsEnds) {
  std::vector<double> t, r, truth;
  for (int k = 0; k < 10; ++k) {
    t.push_back(0.1 * k);
    truth.push_back(141.7 - 0.8 * t.back());
    r.push_back(std::round(truth.back()));
  }
  ASSERT_EQ(r[2], 142.0);
  ASSERT_EQ(r[3], 141.0);
  const std::vector<double> d = dequantize_reference(t, r, whole_millimetres());
  for (std::size_t k = 0; k + 1 < d.size(); ++k) EXPECT_LT(d[k + 1], d[k]) << "row " << k;
  for (std::size_t k = 0; k < d.size(); ++k) {
    EXPECT_LE(std::abs(d[k] - r[k]), 0.5 + 1e-9) << "row " << k;
    EXPECT_LT(std::abs(d[k] - truth[k]), 0.5) << "row " << k;
  }
}

// What the held values do not show is not made up: a value held for most of
// a segment before its only crossing (the axis may have set off from rest
// there), and a ramp of a quantum every 0.3 s that then holds its value for
// 1 s (longer than the ramp's speed allows within one quantum: it stopped)
// are rebuilt flat there.
TEST(RealLogs, AHeldValueBeforeAMoveOrAfterAStopStaysFlat) {
  std::vector<double> t, late, stop;
  for (int k = 0; k < 10; ++k) {
    t.push_back(0.1 * k);
    late.push_back(k < 9 ? 141.0 : 142.0);
  }
  const std::vector<double> d = dequantize_reference(t, late, whole_millimetres());
  for (std::size_t k = 0; k < 8; ++k) EXPECT_DOUBLE_EQ(d[k], 141.0) << "row " << k;
  std::vector<double> ts;
  for (int k = 0; k < 22; ++k) {
    ts.push_back(0.1 * k);
    stop.push_back(50.0 + std::min(k / 3, 4));
  }
  const std::vector<double> e = dequantize_reference(ts, stop, whole_millimetres());
  for (std::size_t k = 13; k < e.size(); ++k) EXPECT_DOUBLE_EQ(e[k], 54.0) << "row " << k;
}

TEST(RealLogs, RoundingIsFoundAsTheLogShowsIt) {
  std::string csv = "t_s,x_ref_mm,x_mm,x_i_A\n";
  for (int k = 0; k < 50; ++k) {
    const double x = 80.0 + 0.9 * k;  // crosses 100 mm: 0.1 mm below, 1 mm above at 3 significant figures
    const double r3 = x >= 100.0 ? std::round(x) : std::round(x * 10.0) / 10.0;
    csv += std::to_string(0.1 * k) + "," + std::to_string(r3) + "," + std::to_string(r3) + ",1\n";
  }
  const PositionRounding sig = detect_rounding(run_from_csv("sig", csv));
  EXPECT_EQ(sig.kind, PositionRounding::Kind::kSignificant);
  EXPECT_EQ(sig.digits, 3);
  EXPECT_DOUBLE_EQ(sig.round(123.4), 123.0);
  EXPECT_DOUBLE_EQ(sig.round(12.34), 12.3);
  std::string fine = "t_s,x_ref_mm,x_mm,x_i_A\n";
  for (int k = 0; k < 50; ++k) fine += std::to_string(0.1 * k) + "," + std::to_string(123.456 + 0.001 * k) + ",1,1\n";
  const PositionRounding dec = detect_rounding(run_from_csv("dec", fine));
  EXPECT_EQ(dec.kind, PositionRounding::Kind::kDecimals);
  EXPECT_EQ(dec.digits, 3);
}

/// A log stitched from three pieces of 30 rows: the axis moves 2 mm a
/// sample where it moves, and jumps 40 mm (and back 25 mm) between pieces.
std::string three_piece_csv() {
  std::string csv = "t_s,x_ref_mm,x_mm,x_i_A\n";
  for (int k = 0; k < 90; ++k) {
    double x = 10.0 + 2.0 * (k % 30);
    if (k >= 30) x += 40.0;
    if (k >= 60) x -= 25.0;
    csv += std::to_string(0.1 * k) + "," + std::to_string(x) + "," + std::to_string(x) + ",1\n";
  }
  return csv;
}

// The three pieces of three_piece_csv are found.
TEST(RealLogs, StitchedSegmentsAreFoundWhereThePositionJumps) {
  std::string note;
  const auto segs = find_segments(run_from_csv("stitched", three_piece_csv()), 0.0, std::nullopt, &note);
  ASSERT_EQ(segs.size(), 3u);
  EXPECT_EQ(segs[0].end, 30u);
  EXPECT_EQ(segs[1].begin, 30u);
  EXPECT_EQ(segs[2].begin, 60u);
  EXPECT_THAT(note, HasSubstr("stitched from 3 segments"));
}

// The replay of some rows: segments wholly outside them are not replayed.
// Each segment's replay starts from its own first row, so the rows of a
// segment replayed come out as in the replay of every segment (exactly: the
// same computation), and the rows of one left out are flagged not compared.
TEST(RealLogs, ReplayingSomeRowsGivesThemAsTheWholeReplayDoes) {
  const MeasuredRun run = run_from_csv("stitched_rows", three_piece_csv());
  const auto segs = find_segments(run, 0.0, std::nullopt, nullptr);
  ASSERT_EQ(segs.size(), 3u);
  const sim::MachineDefinition machine = machine_for_run(run, "", nullptr);
  const PositionRounding rounding = detect_rounding(run);
  std::vector<char> all, some;
  const ReplayResult whole = replay_segments(run, machine, segs, rounding, &all);
  // Rows 35 to 44: inside the second segment only.
  const ReplayResult part = replay_segments(run, machine, segs, rounding, &some, Segment{35, 45});
  ASSERT_EQ(some.size(), all.size());
  for (std::size_t k = 0; k < all.size(); ++k) {
    const bool in_second = k >= segs[1].begin && k < segs[1].end;
    EXPECT_EQ(all[k], 1) << k;
    EXPECT_EQ(some[k], in_second ? 1 : 0) << k;
    if (!in_second) continue;
    EXPECT_EQ(part.x_mm[index(Axis::kX)][k], whole.x_mm[index(Axis::kX)][k]) << k;
    EXPECT_EQ(part.i_A[index(Axis::kX)][k], whole.i_A[index(Axis::kX)][k]) << k;
  }
}

// A stitch on a path: in one row x steps 4 mm and y 4.1 mm (y then turns
// back), each within what the axis holds in its rapids (6 mm a row), so
// neither axis's own rule finds it; the path's step (5.7 mm) is over 4 times
// the steps either side (0.2 and 0.3 mm) with two axes stepping at once,
// which a move of the machine cannot do within one sample and start and end
// at the slow speeds around it. The rapid itself (8.5 mm a row on the path
// for 10 rows, ramping in and out at full step) is not a stitch: its steps
// are matched by their neighbours. Oracle: the row the log was built with.
TEST(RealLogs, AJumpOfSeveralAxesAtOnceWithinWhatEachHoldsIsAStitch) {
  std::string csv = "t_s,x_ref_mm,x_mm,y_ref_mm,y_mm\n";
  double x = 40.0, y = 20.0;
  for (int k = 0; k < 60; ++k) {
    if (k >= 1 && k <= 10) {
      x += 6.0;
      y += 6.0;
    } else if (k >= 20 && k < 40) {
      y += 0.2;
    } else if (k == 40) {
      x += 4.0;
      y += 4.1;
    } else if (k > 40) {
      y -= 0.3;
    }
    csv += fmt::format("{:.1f},{:.1f},{:.1f},{:.1f},{:.1f}\n", 0.1 * k, x, x, y, y);
  }
  std::string note;
  const auto segs = find_segments(run_from_csv("path_stitch", csv), 0.1, std::nullopt, &note);
  ASSERT_EQ(segs.size(), 2u) << note;
  EXPECT_EQ(segs[1].begin, 40u);
  EXPECT_THAT(note, HasSubstr("1 of them where several axes step at once"));
}

// A logger that writes its samples in blocks of 10 rows (1 s at 100 ms) and
// drops every other block, with a continuous clock, as the U-Mich logs are.
// The truth: x and y at 30 and 25 mm/s, turning back at 200 mm/s^2 (a speed
// change of 2 mm a row at most) inside kept blocks, rounded to 0.1 mm. Where
// a dropped block hid 1 s of rapid motion the rows jump 25 to 33 mm, which
// the axis's own rule finds. Across dropped block 21, y stands still and x
// slows to 10 mm/s and turns back: the kept rows step 1, 4 and -1 mm there, a
// step under what x holds in its rapids (3 mm a row, 1.5 times is 4.5 mm)
// and under 4 times its neighbours, on one axis only; a speed held for one
// row only (3 mm off both neighbours against the 2 mm the axis changes by
// inside a block) at a block's boundary is the stitch. Blocks 30, 31 and 32
// are all kept, and x turns back about 31.0 s, across that boundary: a
// change of speed the axis shows inside blocks, not a stitch. Oracle: the
// rows where the log was built with a block dropped before them.
TEST(RealLogs, AStitchAtTheBoundaryOfALoggersBlocksIsFoundWhereASpeedHoldsForOneRow) {
  // Speed keyframes (t_s, v_mm_s), linear between: the truth's motion.
  const std::vector<std::pair<double, double>> vx_key = [] {
    std::vector<std::pair<double, double>> k{{0.0, 0.0}, {0.15, 30.0}};
    double v = 30.0;
    for (double tr : {4.5, 8.5, 12.5, 16.5}) {
      k.push_back({tr, v});
      v = -v;
      k.push_back({tr + 0.3, v});
    }
    // Block 20 slows x to 10 mm/s; it turns back in dropped block 21.
    k.insert(k.end(), {{20.3, v}, {20.4, 10.0}, {21.6, 10.0}, {21.7, -10.0}, {22.5, -10.0}, {22.6, -30.0}});
    v = -30.0;
    for (double tr : {24.5, 28.5, 30.85, 34.5, 38.5}) {
      k.push_back({tr, v});
      v = -v;
      k.push_back({tr + 0.3, v});
    }
    k.push_back({42.0, v});
    return k;
  }();
  const std::vector<std::pair<double, double>> vy_key = [] {
    std::vector<std::pair<double, double>> k{{0.0, 0.0}, {0.125, 25.0}};
    double v = 25.0;
    for (double tr : {2.5, 6.5, 10.5, 14.5, 18.5}) {
      k.push_back({tr, v});
      v = -v;
      k.push_back({tr + 0.25, v});
    }
    k.insert(k.end(), {{20.2, v}, {20.325, 0.0}, {22.3, 0.0}, {22.425, 25.0}});
    v = 25.0;
    for (double tr : {26.5, 30.5, 34.5, 38.5}) {
      k.push_back({tr, v});
      v = -v;
      k.push_back({tr + 0.25, v});
    }
    k.push_back({42.0, v});
    return k;
  }();
  // Positions every 0.1 s, integrating the piecewise-linear speed exactly.
  const auto positions = [](const std::vector<std::pair<double, double>>& key, double x0_mm) {
    std::vector<double> x{x0_mm};
    double pos = x0_mm;
    std::size_t i = 0;
    for (int r = 1; r <= 420; ++r) {
      const double t0 = 0.1 * (r - 1);
      const auto v_at = [&](double t) {
        while (i + 1 < key.size() && key[i + 1].first < t) ++i;
        const auto& [ta, va] = key[i];
        const auto& [tb, vb] = key[std::min(i + 1, key.size() - 1)];
        return tb > ta ? va + (vb - va) * (t - ta) / (tb - ta) : va;
      };
      // Simpson's rule on every millisecond: exact for a speed linear within
      // each one, as here (every keyframe falls on a whole millisecond).
      for (int m = 0; m < 100; ++m) {
        const double a = t0 + 0.001 * m, b = a + 0.001;
        pos += 0.001 / 6.0 * (v_at(a) + 4.0 * v_at(0.5 * (a + b)) + v_at(b));
      }
      x.push_back(pos);
    }
    return x;
  };
  const std::vector<double> x = positions(vx_key, 300.0), y = positions(vy_key, 150.0);
  std::string csv = "t_s,x_ref_mm,x_mm,y_ref_mm,y_mm\n";
  std::vector<std::size_t> expected;
  std::size_t row = 0;
  bool dropped_before = false;
  for (int block = 0; block < 42; ++block) {
    if (block % 2 == 1 && block != 31) {
      dropped_before = true;
      continue;
    }
    if (dropped_before) expected.push_back(row);
    dropped_before = false;
    for (int r = 10 * block; r < 10 * block + 10; ++r, ++row)
      csv += fmt::format("{:.1f},{:.1f},{:.1f},{:.1f},{:.1f}\n", 0.1 * static_cast<double>(row), x[r], x[r], y[r], y[r]);
  }
  std::string note;
  const auto segs = find_segments(run_from_csv("logger_blocks", csv), 0.1, std::nullopt, &note);
  std::vector<std::size_t> found;
  for (std::size_t s = 1; s < segs.size(); ++s) found.push_back(segs[s].begin);
  EXPECT_EQ(found, expected) << note;
  // The stitch after block 21 is the one only the blocks' rule finds.
  EXPECT_THAT(note, HasSubstr("the jumps recur every 10 rows"));
  EXPECT_THAT(note, HasSubstr("1 more at a block's boundary"));
}

// A log whose position leaves its command by more than a metre (an unstable
// loop's, or columns that do not belong together) is refused in one line
// that names the run, the axis and the row, before anything is fitted.
TEST(RealLogs, RunawayLogIsRefusedWithWhereItRanAway) {
  std::string csv = "t_s,x_ref_mm,x_mm,x_i_A\n";
  for (int k = 0; k < 60; ++k) {
    const double ref = 10.0 + 0.5 * k;
    const double x = k < 40 ? ref : ref - 3.0 * std::pow(2.0, k - 40);
    csv += std::to_string(0.1 * k) + "," + std::to_string(ref) + "," + std::to_string(x) + ",1\n";
  }
  const MeasuredRun run = run_from_csv("runaway", csv);
  try {
    calibrate_from_data({run}, {}, machine_for_run(run, "", nullptr));
    FAIL() << "a runaway log was calibrated";
  } catch (const ConfigError& e) {
    // 3 x 2^9 = 1536 mm at row 50 (t = 4.9 s), the first beyond 1000 mm.
    EXPECT_THAT(e.what(), HasSubstr("axis x is 1536 mm from its command at t = 4.9 s (row 50)"));
    EXPECT_THAT(e.what(), HasSubstr("ran away"));
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
  }
}

// A reference of moves back and forth at several speeds with dwells, long
// enough for fitting and held-out parts: the truth's program.
std::vector<double> program(double Ts_s, double scale, double seconds) {
  return truth::moves_program(
      Ts_s, {20.0 * scale, -35.0 * scale, 8.0 * scale, -12.0 * scale, 50.0 * scale, -30.0 * scale}, seconds);
}

truth::RunSpec cascade_spec(double Ts_s) {
  return truth::cascade_run_spec(100.0 / 2.5, 0.0005, Ts_s);  // percent of a 2.5 N m rated torque
}

/// The cascade truth with a Stribeck rise the identified drive does not
/// have (breakaway 0.4 N m above both Coulomb levels, over 2 rad/s).
truth::RunSpec cascade_spec_with_stribeck(double Ts_s) {
  truth::RunSpec sp = cascade_spec(Ts_s);
  sp.effects.stribeck_Ts = 0.4;
  sp.effects.stribeck_ws = 2.0;
  return sp;
}

/// `sp` run on the fitting program and on another (faster moves), written
/// under `name`, and calibrated from the data on the first, validated on
/// the second.
DataCalibration calibrate_on_two_programs(truth::RunSpec sp, const std::string& name) {
  const double Ts = sp.Ts_s;
  sp.reference_mm = program(Ts, 1.0, 24.0);
  const auto fit_dir = work(name + "_fit");
  truth::write_truth_run(fit_dir, sp);
  sp.reference_mm = program(Ts, 1.6, 12.0);
  const auto val_dir = work(name + "_val");
  truth::write_truth_run(val_dir, sp);
  const MeasuredRun fit = load_run(fit_dir), val = load_run(val_dir);
  return calibrate_from_data({fit}, {val}, machine_for_run(fit, "", nullptr));
}

// 1 kHz, velocity command, speed and a raw torque logged: the loop's gains
// are read from the logged signals and the drive is identified in the log's
// unit; the calibrated machine follows another program's tracking error.
TEST(RealLogs, CascadeAtOneKilohertzWithRawTorque) {
  const double Ts = 1e-3;
  truth::RunSpec sp = cascade_spec(Ts);
  sp.reference_mm = program(Ts, 1.0, 24.0);
  const auto fit_dir = work("cascade_fit");
  truth::write_truth_run(fit_dir, sp);
  sp.reference_mm = program(Ts, 1.6, 12.0);  // another program: faster moves
  const auto val_dir = work("cascade_val");
  truth::write_truth_run(val_dir, sp);
  const MeasuredRun fit = load_run(fit_dir), val = load_run(val_dir);
  const sim::MachineDefinition nominal = machine_for_run(fit, "", nullptr);
  const DataCalibration r = calibrate_from_data({fit}, {val}, nominal);
  ASSERT_EQ(r.axis.size(), 1u);
  const AxisFromData& ax = r.axis[0];
  ASSERT_TRUE(ax.identified) << ax.note;
  EXPECT_EQ(ax.channel.column, "x_torque_raw");
  // Kvp in raw per mm/s (rg = 1 mm/rad in the identified drive).
  expect_truth_gains(ax, sp);
  // Friction in the log's unit: moving levels Tc + load, 10 % (the fit
  // sees the truth's B and J through a 1 kHz log of the commanded motion).
  const double scale = sp.cascade.raw_per_Nm;
  EXPECT_NEAR(ax.Tc_pos + ax.c, scale * (0.25 + 0.05), 0.1 * scale * 0.30);
  EXPECT_NEAR(ax.Tc_neg - ax.c, scale * (0.15 - 0.05), 0.1 * scale * 0.30);
  // The truth's levels differ by 0.1 N m: one level for both would miss each
  // direction by half that, and the held-out replay keeps the two.
  EXPECT_FALSE(ax.one_coulomb_level) << ax.coulomb_choice;
  EXPECT_THAT(ax.coulomb_choice, HasSubstr("a Coulomb level per direction"));
  expect_held_out_check(r);
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const auto& e = r.validation_runs[0].calibrated.nrms;
  // The logged velocity command is a channel too (spec/interfaces.md): the
  // twin's, from the same P law on its own following error, within 2 % NRMS
  // (the velocity feedforward carries most of it; the rest is Kv times an
  // error known to 1 %), against 1 for the zero model.
  ASSERT_TRUE(e.count("x_vcmd_mm_s"));
  EXPECT_LT(e.at("x_vcmd_mm_s"), 0.02);
  EXPECT_DOUBLE_EQ(r.validation_runs[0].zero.nrms.at("x_vcmd_mm_s"), 1.0);
  // One validation run: its pooled errors are its own.
  for (const auto& [k, v] : e) EXPECT_NEAR(r.pooled_validation.calibrated.nrms.at(k), v, 1e-12) << k;
  // The machine as written to machine.yaml and read back as `twin replay
  // OTHER --machine OUT/machine.yaml` reads it (machine_for_run: the run's
  // meta.json gives the controller period and the encoder) gives the same
  // numbers. (The encoder the calibration closed its loop on was the 0.1 um
  // the commands are logged to, and the replay's the meta's 0.5 um: the
  // run without an effect of the cascade sweep gave tracking 0.0024 and
  // torque 0.057 NRMS in the report, 0.0015 and 0.011 in `twin replay`.)
  const auto yaml_dir = work("cascade_yaml");
  io::write_file_atomic(yaml_dir / "machine.yaml", io::machine_to_yaml(r.final_machine, "test"));
  const sim::MachineDefinition back = machine_for_run(val, (yaml_dir / "machine.yaml").string(), nullptr);
  EXPECT_DOUBLE_EQ(back.encoder_resolution_mm, sp.resolution_mm);
  const RunErrors again = evaluate_machine_on_run(val, back, nullptr, nullptr);
  for (const auto& [k, v] : e) {
    ASSERT_TRUE(again.calibrated.nrms.count(k)) << k;
    EXPECT_DOUBLE_EQ(again.calibrated.nrms.at(k), v) << k;
  }
}

/// The cascade truth logged as the U-Mich mill logs: every 100 ms, positions
/// to 3 significant figures, the current in A and no velocity channel; no
/// feedforward.
truth::RunSpec coarse_current_spec(double Ts_s) {
  truth::RunSpec sp = cascade_spec(Ts_s);
  sp.cascade.raw_per_Nm = 0.0;
  sp.cascade.log_velocities = false;
  sp.cascade.kff = 0.0;
  sp.log_every = 100;
  sp.log_significant_figures = 3;
  return sp;
}

// 100 ms, positions to 3 significant figures, current only, stitched from
// two recordings: the calibration finishes, finds the stitch and the
// rounding, reports the lag of the position (1 - kff) / Kv within 25 % (the
// rounded positions carry it statistically), and reports both baselines.
// The twin against the regression with the scatter of the rows: the paired
// difference must be the two NRMS of the table subtracted (the same rows;
// 1e-3 covers their rounding to 4 significant digits), inside its own
// interval, and said in report.md.
TEST(RealLogs, CoarseRoundedStitchedCurrentLog) {
  const double Ts = 1e-3;
  truth::RunSpec sp = coarse_current_spec(Ts);
  std::vector<double> ref = program(Ts, 0.4, 60.0);
  sp.reference_mm = ref;
  const auto a = work("coarse_a");
  truth::write_truth_run(a, sp);
  // Stitch: the first 300 rows of the run, then a piece recorded elsewhere (+70 mm).
  for (double& x : sp.reference_mm) x += 70.0;
  const auto b = work("coarse_b");
  truth::write_truth_run(b, sp);
  std::ifstream fa(a / "trace.csv"), fb(b / "trace.csv");
  std::string line, header;
  std::getline(fa, header);
  std::getline(fb, line);
  std::vector<std::string> rows_a, rows_b;
  while (std::getline(fa, line)) rows_a.push_back(line);
  while (std::getline(fb, line)) rows_b.push_back(line);
  const auto d = work("coarse_stitched");
  std::filesystem::copy_file(a / "meta.json", d / "meta.json");
  std::ofstream out(d / "trace.csv");
  out << header << "\n";
  for (std::size_t k = 0; k < rows_a.size(); ++k) {
    const std::string& src = k < 300 ? rows_a[k] : rows_b[k];
    out << src << "\n";
  }
  out.close();
  const MeasuredRun run = load_run(d);
  const DataCalibration r = calibrate_from_data({run}, {}, machine_for_run(run, "", nullptr));
  EXPECT_TRUE(has_note(r, "stitched from 2 segments"));
  EXPECT_TRUE(has_note(r, "3 significant figures"));
  ASSERT_EQ(r.axis.size(), 1u);
  EXPECT_NEAR(r.axis[0].lag_s, 1.0 / 45.0, 0.25 / 45.0);
  ASSERT_EQ(r.fit_runs.size(), 1u);
  EXPECT_TRUE(r.fit_runs[0].regression.nrms.count("x_i_A"));
  EXPECT_TRUE(r.fit_runs[0].calibrated.nrms.count("x_i_A"));
  EXPECT_DOUBLE_EQ(r.fit_runs[0].zero.nrms.at("x_i_A"), 1.0);
  const auto j = data_calibration_report_json(r);
  EXPECT_TRUE(j.contains("baseline"));
  EXPECT_TRUE(j["effects_skipped"].contains("cogging"));
  ASSERT_TRUE(r.fit_runs[0].twin_minus_regression.count("x_i_A"));
  const PairedDifference& p = r.fit_runs[0].twin_minus_regression.at("x_i_A");
  EXPECT_NEAR(p.difference, r.fit_runs[0].calibrated.nrms.at("x_i_A") - r.fit_runs[0].regression.nrms.at("x_i_A"),
              1e-3);
  EXPECT_LE(p.lo, p.difference);
  EXPECT_GE(p.hi, p.difference);
  EXPECT_GE(p.blocks, 2u);
  EXPECT_TRUE(j["fit_runs"][0]["twin_minus_regression"].contains("x_i_A"));
  // The block where the twin loses most, where it loses on any: its times
  // are the log's, inside the held-out part, and the row count the block's;
  // none in the report where it loses on none.
  if (p.largest_loss_rows > 0) {
    const auto& loss = j["fit_runs"][0]["twin_minus_regression"]["x_i_A"]["largest_loss"];
    const auto& t = run.trace.at("t_s");
    EXPECT_GE(loss["from_s"].get<double>(), t[r.fit_runs[0].rows * 6 / 10 - 1]);
    EXPECT_LE(loss["from_s"].get<double>(), loss["to_s"].get<double>());
    EXPECT_LE(loss["to_s"].get<double>(), t.back());
    EXPECT_EQ(loss["rows"].get<std::size_t>(), p.largest_loss_rows);
  } else {
    EXPECT_FALSE(j["fit_runs"][0]["twin_minus_regression"]["x_i_A"].contains("largest_loss"));
  }
  EXPECT_THAT(data_calibration_report_markdown(r, "coarse_stitched"), HasSubstr("The twin against the regression, with the scatter"));
}

// A log shaped like the U-Mich mill's: 100 ms, positions to 3 significant
// figures, the current in A and no velocity channel, of the truth's cascade
// (Kvp 0.4 N m s/rad, Tn 10 ms, no feedforward) without an effect. The
// acceptance's cross-program check: calibrated on one program, the machine
// predicts another program's current (0.7 times the speeds, 40 s, another
// seed) better than the rigid-body regression fitted on the first and than
// the machine as identified. Oracle: the truth simulator's run of the other
// program. Measured: 0.579 against the regression's 0.620 and the identified
// machine's 0.593; the check is the order, not a margin. (The fitting run's
// own held-out rows are lost to the regression there, 0.671 against 0.619,
// and effects the truth does not hold are kept: docs/calibration.md, "Not
// resolved".)
TEST(RealLogs, ACoarseCurrentLogPredictsAnotherProgramBetterThanTheRegression) {
  const double Ts = 1e-3;
  truth::RunSpec sp = coarse_current_spec(Ts);
  sp.cascade.Kvp = 0.4;
  sp.cascade.Tn = 0.01;
  sp.reference_mm = program(Ts, 0.4, 60.0);
  const auto fit_dir = work("coarse_fit");
  truth::write_truth_run(fit_dir, sp);
  sp.reference_mm = program(Ts, 0.7, 40.0);
  sp.seed = 7;
  const auto val_dir = work("coarse_val");
  truth::write_truth_run(val_dir, sp);
  const MeasuredRun run = load_run(fit_dir);
  const MeasuredRun val = load_run(val_dir);
  const DataCalibration r = calibrate_from_data({run}, {val}, machine_for_run(run, "", nullptr));
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const RunErrors& v = r.validation_runs[0];
  ASSERT_TRUE(v.calibrated.nrms.count("x_i_A") && v.regression.nrms.count("x_i_A"));
  EXPECT_LT(v.calibrated.nrms.at("x_i_A"), v.regression.nrms.at("x_i_A"));
  EXPECT_LE(v.calibrated.nrms.at("x_i_A"), v.identified.nrms.at("x_i_A"));
}

// The same truth logged every 10 ms, and every 1 ms (positions to 3
// significant figures: 0.1 mm here), current only. Its loop rings at about
// 10 Hz for 0.3 s after every change of speed, so the current at a row is
// mostly the ringing's, which the command's acceleration at the row does
// not show: fitted on the rows, J came out at 0.001 (10 ms) and 5e-5 (1 ms)
// A per mm/s^2, every velocity loop was chosen about that J, and the twin
// lost to the regression (held out 0.784 against 0.766 at 10 ms). Oracle:
// the truth's J, 0.0084 kg m^2 over Kt rg = 0.4769 N m/A x 1.5915 mm/rad,
// i.e. 0.01107 A per mm/s^2; the windows between steady rows must give it
// within 10 % (found 3.7 % and 7 % low: the axis's lag behind a cruise adds
// B times it, and the line speeds carry the rounding), say so in the
// axis's note, and the twin must then beat the regression on the run's
// held-out rows and on the other program (measured 0.609 against 0.766 and
// 0.627 against 0.755 at 10 ms; 0.571 against 0.800 and 0.631 against
// 0.802 at 1 ms). The 100 ms log of the test above keeps the rows' J: its
// windows do not resolve J to a tenth.
TEST(RealLogs, InertiaAStaircaseLogDoesNotResolveIsTakenFromTheTorquesIntegral) {
  const double Ts = 1e-3;
  const double J_truth = 0.0084 / (0.4769 * 1.5915);
  for (const int every : {10, 1}) {
    truth::RunSpec sp = coarse_current_spec(Ts);
    sp.log_every = every;
    sp.cascade.Kvp = 0.4;
    sp.cascade.Tn = 0.01;
    sp.reference_mm = program(Ts, 0.4, 60.0);
    const auto fit_dir = work(fmt::format("windows_fit_{}", every));
    truth::write_truth_run(fit_dir, sp);
    sp.reference_mm = program(Ts, 0.7, 40.0);
    sp.seed = 7;
    const auto val_dir = work(fmt::format("windows_val_{}", every));
    truth::write_truth_run(val_dir, sp);
    const MeasuredRun run = load_run(fit_dir);
    const MeasuredRun val = load_run(val_dir);
    const DataCalibration r = calibrate_from_data({run}, {val}, machine_for_run(run, "", nullptr));
    ASSERT_EQ(r.axis.size(), 1u);
    EXPECT_NEAR(r.axis[0].J, J_truth, 0.1 * J_truth) << every;
    EXPECT_THAT(r.axis[0].note, HasSubstr("from the torque's integral over")) << every;
    ASSERT_EQ(r.fit_runs.size(), 1u);
    ASSERT_EQ(r.validation_runs.size(), 1u);
    const RunErrors& f = r.fit_runs[0];
    const RunErrors& v = r.validation_runs[0];
    ASSERT_TRUE(f.calibrated.nrms.count("x_i_A") && f.regression.nrms.count("x_i_A"));
    ASSERT_TRUE(v.calibrated.nrms.count("x_i_A") && v.regression.nrms.count("x_i_A"));
    EXPECT_LT(f.calibrated.nrms.at("x_i_A"), f.regression.nrms.at("x_i_A")) << every;
    EXPECT_LT(v.calibrated.nrms.at("x_i_A"), v.regression.nrms.at("x_i_A")) << every;
  }
}

// Logs without the position loop's output: the 1 kHz runs of
// CascadeAtOneKilohertzWithRawTorque with a Stribeck rise in the truth's
// friction (which the identified drive does not have), the velocity command
// held at 0 on every row (a dead channel), and once without the speed too.
// The position alone shows only the lag (1 - kff) / Kv, and a P loop
// without feedforward at that lag missed the other program's following
// error by 0.044 NRMS here (0.08 on the cascade sweep's Stribeck run). The
// cascade's velocity loop acts on vcmd - v, so the torque carries the
// command: rebuilt from it, the gains must come out as where the command is
// logged (oracle: the truth's Kv 45 1/s and kff 0.6; 2 %, against the 1 % of
// the logged command, for the speed's noise and, without the speed, the
// 50 Hz filter of the one taken from the position), and the following error
// within 1 % NRMS on the other program.
TEST(RealLogs, ADeadVelocityCommandIsRebuiltFromTheTorque) {
  const double Ts = 1e-3;
  truth::RunSpec sp = cascade_spec(Ts);
  sp.effects.stribeck_Ts = 0.1;  // a Stribeck rise the drive does not have
  sp.effects.stribeck_ws = 2.0;
  // The truth run of `ref` with the velocity command written as 0 (and,
  // without `speed`, no speed column).
  auto log_without_command = [&](const std::string& name, const std::vector<double>& ref, bool speed) {
    sp.reference_mm = ref;
    const auto whole = work(name + "_whole");
    truth::write_truth_run(whole, sp);
    std::vector<std::string> head;
    return rewritten_run(whole, name, [&](std::ptrdiff_t row, std::string& line) {
      std::vector<std::string> cells;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
      if (row < 0) head = cells;
      line.clear();
      for (std::size_t j = 0; j < cells.size(); ++j)
        if (speed || head[j] != "x_v_mm_s")
          line += (line.empty() ? "" : ",") + (row >= 0 && head[j] == "x_vcmd_mm_s" ? "0" : cells[j]);
      return true;
    });
  };
  for (const bool speed : {true, false}) {
    SCOPED_TRACE(speed ? "speed logged" : "no speed logged");
    const std::string tag = speed ? "_v" : "_nov";
    const MeasuredRun fit = log_without_command("dead_vcmd_fit" + tag, program(Ts, 1.0, 24.0), speed);
    const MeasuredRun val = log_without_command("dead_vcmd_val" + tag, program(Ts, 1.6, 12.0), speed);
    EXPECT_EQ(fit.trace.find("x_vcmd_mm_s"), nullptr);
    const DataCalibration r = calibrate_from_data({fit}, {val}, machine_for_run(fit, "", nullptr));
    EXPECT_TRUE(has_note(r, "x_vcmd_mm_s holds 0 over the whole run"));
    EXPECT_TRUE(has_note(r, "no velocity command logged: rebuilt"));
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_TRUE(ax.identified) << ax.note;
    EXPECT_NEAR(ax.gains.Kv_per_s, 45.0, 0.9) << ax.loop_source;
    EXPECT_NEAR(ax.gains.kff, 0.6, 0.012) << ax.loop_source;
    EXPECT_THAT(ax.loop_source, HasSubstr("rebuilt from the logged torque"));
    EXPECT_TRUE(ax.velocity_loop_from_data) << ax.loop_source;
    expect_held_out_check(r);
    // The command the twin rebuilt is not a logged channel: never compared.
    ASSERT_EQ(r.validation_runs.size(), 1u);
    EXPECT_FALSE(r.validation_runs[0].calibrated.nrms.count("x_vcmd_mm_s"));
    EXPECT_FALSE(r.fit_runs[0].calibrated.nrms.count("x_vcmd_mm_s"));
  }
}

// A velocity command logged a row late (or two rows early) against the
// position it is computed from, in both runs of
// CascadeAtOneKilohertzWithRawTorque: every law fitted across that skew is
// off (the cascade sweep's validation tracking went to 0.026 to 0.11 NRMS).
// Moved back into line for the identification, the gains must be those of
// the aligned log (oracle: the truth's Kv 45 1/s and kff 0.6, to the 1 % of
// that test) and the other program's following error within 1 % NRMS; the
// errors still compare the command as logged.
TEST(RealLogs, AVelocityCommandLoggedRowsOffIsMovedBackIntoLine) {
  const double Ts = 1e-3;
  truth::RunSpec sp = cascade_spec(Ts);
  auto skewed = [&](const std::string& name, const std::vector<double>& ref, int skew) {
    sp.reference_mm = ref;
    const auto d = work(name);
    truth::write_truth_run(d, sp);
    MeasuredRun run = load_run(d);
    auto& c = run.trace.columns[static_cast<std::size_t>(
        std::find(run.trace.names.begin(), run.trace.names.end(), "x_vcmd_mm_s") - run.trace.names.begin())];
    const std::vector<double> logged = c;
    for (std::size_t k = 0; k < c.size(); ++k)
      c[k] = logged[static_cast<std::size_t>(std::clamp<std::ptrdiff_t>(static_cast<std::ptrdiff_t>(k) - skew, 0,
                                                                        static_cast<std::ptrdiff_t>(c.size()) - 1))];
    return run;
  };
  for (const int skew : {1, -2}) {
    SCOPED_TRACE(skew);
    const MeasuredRun fit = skewed("skew_fit", program(Ts, 1.0, 24.0), skew);
    const MeasuredRun val = skewed("skew_val", program(Ts, 1.6, 12.0), skew);
    const DataCalibration r = calibrate_from_data({fit}, {val}, machine_for_run(fit, "", nullptr));
    EXPECT_TRUE(has_note(r, fmt::format("x_vcmd_mm_s is logged {} {} {}", std::abs(skew),
                                        std::abs(skew) == 1 ? "row" : "rows", skew > 0 ? "after" : "before")));
    ASSERT_EQ(r.axis.size(), 1u);
    EXPECT_NEAR(r.axis[0].gains.Kv_per_s, 45.0, 0.45);
    EXPECT_NEAR(r.axis[0].gains.kff, 0.6, 0.01);
    expect_held_out_check(r);
    ASSERT_EQ(r.validation_runs.size(), 1u);
    EXPECT_TRUE(r.validation_runs[0].calibrated.nrms.count("x_vcmd_mm_s"));
  }
}

// A 1 ms cascade logged every 2 and every 4 ms (meta.json gives both
// periods), with a Stribeck rise in the truth the identified drive does not
// have. The loop takes its command's speed over its own period and sums the
// speed error every period; fitted on the log's own differences and sums,
// the laws came out at Kv 43.8 and kff 0.61 and Kvp 6 % low at 2 ms, and at
// 4 ms (where the velocity loop was not fitted from the log) the other
// program's tracking at 0.117 NRMS. Oracle: the truth's Kv 45 1/s
// and kff 0.6 to the 1 % of the 1 kHz test, and its Kvp and Tn to the 5 %
// and 10 % of that test; the held-out machine's check on the other program.
TEST(RealLogs, ALogSlowerThanTheLoopIsFittedAtTheLoopsPeriod) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  for (const int every : {2, 4}) {
    SCOPED_TRACE(every);
    sp.log_every = every;
    const DataCalibration r = calibrate_on_two_programs(sp, "slow");
    EXPECT_TRUE(has_note(r, "controller period 0.001 s from meta.json"));
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_TRUE(ax.identified) << ax.note;
    expect_truth_gains(ax, sp);
    expect_held_out_check(r);
  }
}

// A 1 ms cascade logged every 10 and every 20 ms, with the velocity
// command, the motor's speed and a raw torque, and a Stribeck rise the
// identified drive does not have. The velocity loop (59 rad/s, its PI zero
// at 125 rad/s) lies under those logs' Nyquist rates of 314 and 157 rad/s,
// yet it was fitted from the log only at 5 ms or faster; slower, its gains
// were chosen blind among 16 (Kvp near twice the truth's) and the other
// program tracked at 0.025 NRMS at both rates (the sweep's run without an
// effect). Now the law is fitted up to 20 ms, and taken where it explains
// the torque's change from row to row: its integral, summed once a row,
// drifts over a segment by more than the level test allows at 20 ms, and
// the first coefficient, Kvp less Ki (dt - Ts) / 2, is negative there.
// Oracles: the truth's Kvp (5 %) and Tn (10 %) as for the faster logs; Kv
// and kff to 1 % at both rates (the P law at 20 ms came out 1.6 % high on
// every row, the reference's speed over the loop's period read off the
// cubic between rows 20 ms apart; it is fitted on the rows where that
// speed is exact now); the held-out machine's check on the other program.
TEST(RealLogs, ALogOfTenOrTwentyMillisecondsShowsTheVelocityLoop) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  for (const int every : {10, 20}) {
    SCOPED_TRACE(every);
    sp.log_every = every;
    const DataCalibration r = calibrate_on_two_programs(sp, fmt::format("slower_{}", every));
    EXPECT_FALSE(has_note(r, "no speed logged for x"));
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_TRUE(ax.identified) << ax.note;
    expect_truth_gains(ax, sp);
    expect_held_out_check(r);
  }
}

// A limit on the motor's current (8 A: 152.6 raw) behind the 1 ms loop,
// logged every 10 ms with the velocity command, the motor's speed and the
// raw torque, on the cascade sweep's programs of moves (the limit reached in
// the fastest accelerations only). It holds the log for a few rows, under
// the 10 (10 ms at 1 kHz) the law's fit and the saturation detector asked
// for: the law was fitted through the clipped rows, the limit never looked
// at, no effect named, and the other program tracked at 0.0058. Now 4 rows
// on logs slower than 5 ms that the law is read from, and the law's polish
// replays with the motor's current clamped at the level the law's fit left
// out. Oracles: the truth's limit (its level within 2 %, as at 1 kHz in
// data_effects_test.cpp: the flat top's median), no other effect, and the
// held-out check on the other program (0.0025 when the figures were taken).
TEST(RealLogs, ATenMillisecondLogShowsACurrentLimit) {
  const double limit_raw = 40.0 * 0.4769 * 8.0;
  truth::RunSpec sp = truth::cascade_run_spec(40.0, 0.001);
  sp.effects.i_max_A = 8.0;
  sp.log_every = 10;
  sp.reference_mm = truth::moves_program(sp.Ts_s, {20.0, -35.0, 3.0, -12.0, 50.0, -30.0, 8.0, -4.0, 25.0, -25.0}, 24.0);
  const auto fit_dir = work("limit_10_fit");
  truth::write_truth_run(fit_dir, sp);
  sp.reference_mm = truth::moves_program(sp.Ts_s, {30.0, -45.0, 5.0, -15.0, 40.0, -6.0, 12.0, -20.0}, 16.0);
  const auto val_dir = work("limit_10_val");
  truth::write_truth_run(val_dir, sp);
  const MeasuredRun fit = load_run(fit_dir), val = load_run(val_dir);
  const DataCalibration r = calibrate_from_data({fit}, {val}, machine_for_run(fit, "", nullptr));
  ASSERT_EQ(r.axis.size(), 1u);
  std::vector<std::string> kept;
  for (const DataEffect& e : r.effects)
    if (e.kept) kept.push_back(e.effect);
  ASSERT_EQ(kept, std::vector<std::string>{"current_saturation"}) << r.axis[0].loop_source;
  const auto limit = std::find_if(r.effects.begin(), r.effects.end(), [](const DataEffect& e) { return e.kept; });
  EXPECT_NEAR(limit->params.at("i_max_A"), limit_raw, 0.02 * limit_raw);
  expect_held_out_check(r);
}

/// The Stribeck truth of the tests above logged every `every` loop periods
/// without the motor's speed.
truth::RunSpec stribeck_logged_without_speed(int every) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  sp.log_every = every;
  sp.cascade.log_motor_speed = false;
  return sp;
}

// The same 10 ms log without the motor's speed (the position loop's command
// and output, and the torque, as many CNCs trace them). The speed was taken
// from the position only at 5 ms or faster, so the velocity loop was not
// read and all 14 runs of the sweep missed the tracking check (0.025 to
// 0.12). Now at 20 ms or faster; slower than 6.7 ms as the five-point
// difference, not low-passed (the 50 Hz low-pass is at that log's Nyquist
// rate): the central difference's gain of 0.76 at the loop's 20 Hz ringing
// put Kvp at 16.3 for 12.6 (13.05 now, Tn 8.2 ms). Oracles: the truth's
// gains to the tolerances of the logged speed's (Kvp 5 %, Tn 10 %, Kv and
// kff 1 %) and the held-out check on the other program (0.0039 tracking).
TEST(RealLogs, ATenMillisecondLogWithoutTheSpeedShowsTheVelocityLoop) {
  const truth::RunSpec sp = stribeck_logged_without_speed(10);
  const DataCalibration r = calibrate_on_two_programs(sp, "slower_10_no_speed");
  EXPECT_TRUE(has_note(r, "no speed logged for x: taken as the five-point difference"));
  ASSERT_EQ(r.axis.size(), 1u);
  const AxisFromData& ax = r.axis[0];
  ASSERT_TRUE(ax.identified) << ax.note;
  expect_truth_gains(ax, sp);
  expect_held_out_check(r);
}

// The same truth logged every 20 ms without the motor's speed. The law is
// read there on the five-point difference of the position, whose gain at
// the loop's 20 Hz ringing (0.4 of the log's rate) is 0.38: the integral's
// gain Ki = Kvp / Tn comes out near the truth's and Kvp far above it (18.4
// and 11.1 ms for the truth's 12.6 and 8 ms). That loop lost on the fitting
// rows' torque to a P loop of the 16 chosen blind, which tracked those rows
// at 0.118 (no integral against the Stribeck rise). Now the law's Kvp and Ki
// are polished on the replay of the fitting rows (14.3 and 8.2 ms), and the
// 16 win only where they do not track those rows worse. Oracles: the
// truth's gains, to 16 % on Kvp and 15 % on Tn (the polish fits the outputs
// of a drive that has no Stribeck rise yet, so it comes only as near the
// truth's loop as that drive allows: Kvp 13.3 when the twin's torque at a
// row was its mean over the two sample periods about it, 14.3 with the
// reference rebuilt through the speed the logged command shows and the
// torque taken at the row, where the other program's torque NRMS is 0.15
// against 0.26), and the held-out check on the other program (tracking
// 0.0042).
TEST(RealLogs, ATwentyMillisecondLogWithoutTheSpeedShowsTheVelocityLoop) {
  const truth::RunSpec sp = stribeck_logged_without_speed(20);
  const DataCalibration r = calibrate_on_two_programs(sp, "slower_20_no_speed");
  EXPECT_TRUE(has_note(r, "no speed logged for x: taken as the five-point difference"));
  ASSERT_EQ(r.axis.size(), 1u);
  const AxisFromData& ax = r.axis[0];
  ASSERT_TRUE(ax.identified) << ax.note;
  EXPECT_TRUE(ax.velocity_loop_from_data) << ax.loop_source;
  EXPECT_NE(ax.loop_source.find("polished on the replay"), std::string::npos) << ax.loop_source;
  const double Kvp = 0.5 / sp.plant.rg * 40.0;
  EXPECT_NEAR(ax.gains.Kvp_torque_s_per_rad, Kvp, 0.16 * Kvp) << ax.loop_source;
  EXPECT_NEAR(ax.gains.Tn_s, 0.008, 0.0012) << ax.loop_source;
  expect_held_out_check(r);
}

/// `sp` run at its loop's rate on `ref`, written under `name` as a log every
/// `every` periods whose torque at a row is the mean of the `every` periods
/// that end there (a logger that averages over its sample period).
MeasuredRun averaged_log(truth::RunSpec sp, const std::vector<double>& ref, int every, const std::string& name) {
  sp.reference_mm = ref;
  sp.log_every = 1;
  const auto fine_dir = work(name + "_fine");
  truth::write_truth_run(fine_dir, sp);
  const MeasuredRun fine = load_run(fine_dir);
  const auto d = work(name);
  std::ofstream(d / "meta.json") << fmt::format(
      R"({{"machine": null, "axes": ["x"], "controller_period_s": {}, "sample_period_s": {}, "encoder_resolution_mm": {}}})",
      sp.Ts_s, every * sp.Ts_s, sp.resolution_mm);
  std::ofstream csv(d / "trace.csv");
  csv << fmt::format("{}\n", fmt::join(fine.trace.names, ","));
  const auto n = static_cast<std::ptrdiff_t>(fine.trace.num_rows());
  for (std::ptrdiff_t k = every - 1; k < n; k += every) {
    std::vector<std::string> row;
    for (std::size_t c = 0; c < fine.trace.names.size(); ++c) {
      const std::vector<double>& col = fine.trace.columns[c];
      double v = col[static_cast<std::size_t>(k)];
      if (fine.trace.names[c] == "x_torque_raw") {
        v = 0.0;
        for (std::ptrdiff_t j = k - every + 1; j <= k; ++j) v += col[static_cast<std::size_t>(j)];
        v /= every;
      }
      row.push_back(fine.trace.names[c] == "t_s" ? fmt::format("{:.4f}", v - (every - 1) * sp.Ts_s)
                                                 : fmt::format("{:.9g}", v));
    }
    csv << fmt::format("{}\n", fmt::join(row, ","));
  }
  csv.close();
  return load_run(d);
}

// The 1 ms truth logged every 10 ms by a logger that averages the torque
// over the 10 periods that end at each row. The PI law fitted on that
// torque reads its lag as the law's: Kvp 4.4 and Tn 2.7 ms (the truth's
// 12.6 and 8 ms), a loop whose replay ran away on both programs ("the
// replay failed: axis x unstable"), so the calibrated machine gave no
// figure at all. On logs slower than 5 ms the law read from the log now
// stands against the 16 loops chosen without it, on the fitting rows.
// Oracle: the truth's loop is stable, so its replay must be: the tracking
// and torque errors of the other program computed, and the torque below
// the regression's (0.35 against 0.44; the loop chosen blind tracks at
// 0.11, as on logs that do not show the velocity loop).
TEST(RealLogs, AVelocityLawThatRunsAwayIsNotKept) {
  const truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  const MeasuredRun fit = averaged_log(sp, program(1e-3, 1.0, 24.0), 10, "averaged_fit");
  const MeasuredRun val = averaged_log(sp, program(1e-3, 1.6, 12.0), 10, "averaged_val");
  const DataCalibration r = calibrate_from_data({fit}, {val}, machine_for_run(fit, "", nullptr));
  ASSERT_EQ(r.axis.size(), 1u);
  const AxisFromData& ax = r.axis[0];
  ASSERT_TRUE(ax.identified) << ax.note;
  EXPECT_FALSE(ax.velocity_loop_from_data) << ax.loop_source;
  EXPECT_THAT(ax.loop_source, HasSubstr("not kept: it replays the fitting rows' x_torque_raw to no figure"));
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const auto& e = r.validation_runs[0].calibrated.nrms;
  ASSERT_TRUE(e.count("x_err_mm")) << "the replay of the other program failed";
  ASSERT_TRUE(e.count("x_torque_raw"));
  EXPECT_LT(e.at("x_torque_raw"), r.validation_runs[0].regression.nrms.at("x_torque_raw"));
}

// A 1 ms cascade with a 2 ms dead time before its torque (the truth's
// delay), logged every 4 ms, and without a delay alike: the dead time is
// half a row. Searched in whole rows, and with the catalogue's delay,
// cogging and load friction left out of logs slower than 2 ms, the delay was
// not tried and the other program tracked at 0.040 NRMS. Now the law's lag
// is searched in loop periods (the columns between two rows off the cubic
// through the four about), and the torque held over the loop's period is
// tried for the drive's timing (the speed one period on off the same
// cubic). Oracles: the truth's 2 ms to 1e-9 s (whole loop periods) and
// none where it has none; the truth's gains as for the 1 kHz log (the law
// refitted at the lag, Kvp 5 % and Tn 10 %); the held-out machine's check
// on the other program (0.0045 with the delay: 0.0103 where the drive is
// fitted on the central difference, its J 1.7 % high and its Coulomb levels
// 1.7 % low, and a dead time's loop the least damped).
//
// Without the motor's speed the speed was taken from the position only on
// logs at 2 ms or faster: at 4 ms the drive was fitted on the commanded
// kinematics, the velocity loop not seen, and 14 of the sweep's 14 runs
// missed the tracking check (0.025 to 0.08). Now on every log that resolves
// the velocity loop; the same oracles (the torque's timing is not chosen on
// a speed taken through the low-pass).
TEST(RealLogs, ADelayOfHalfARowIsFoundOnALogSlowerThanTheLoop) {
  for (const bool motor_speed : {true, false})
    for (const int delay_ticks : {2, 0}) {
      SCOPED_TRACE(fmt::format("{}, dead time {} periods", motor_speed ? "speed logged" : "no speed", delay_ticks));
      truth::RunSpec sp = cascade_spec(1e-3);
      sp.log_every = 4;
      sp.cascade.log_motor_speed = motor_speed;
      sp.effects.delay_ticks = delay_ticks;
      const DataCalibration r =
          calibrate_on_two_programs(sp, fmt::format("half_row_{}_{}", motor_speed ? "v" : "x", delay_ticks));
      EXPECT_EQ(has_note(r, "no speed logged for x"), !motor_speed);
      ASSERT_EQ(r.axis.size(), 1u);
      const AxisFromData& ax = r.axis[0];
      ASSERT_TRUE(ax.identified) << ax.note;
      expect_delay_kept(r, 1e-3 * delay_ticks);
      AxisFromData at_lag = ax;  // the gains the delay is replayed with
      at_lag.gains = ax.gains_at_lag;
      expect_truth_gains(at_lag, sp);
      EXPECT_NEAR(ax.torque_lag_rows(), 0.25 * delay_ticks, 1e-12) << ax.loop_source;
      if (motor_speed) {
        EXPECT_THAT(ax.torque_timing, HasSubstr("loop period")) << ax.torque_timing;
      }
      expect_held_out_check(r);
    }
}

// A 2 ms position loop over a 1 ms velocity loop, traced every 1 ms, with a
// 1 ms dead time before its torque (half the position loop's period: one
// velocity-loop tick), and without one alike. The law's lag was searched in
// whole rows of the loop's ticks: the dead time was read as a torque logged
// as the period's mean (the other program tracked at 0.0172 NRMS); found at
// half a row off the cubic it was not kept (0.0084), as the drive was fitted
// on the ticks' torques at lag 0. Now the lag is searched in the velocity
// loop's ticks, the law's columns taken at the tick, and the drive fitted on
// the torques the ticks apply over each row, the dead time's ticks behind.
// The same under a 4 ms position loop with a 2 ms dead time (two ticks of
// four): searched in whole rows no dead time was proposed (rising friction
// was kept) and the other program tracked at 0.050 (now 0.0051). Oracles:
// the truth's dead time to 1e-9 s and none where it has none; its gains as
// for the 1 kHz log (Kvp 5 %, Tn 10 %); J to 1 % of the truth's (0.0084
// kg m^2 in the raw unit) behind a dead time, where the loop is the least
// damped and its following error went from 0.0019 to 0.0130 NRMS as J went
// 1.3 % high, and to 1.5 % without one (the ticks' torques over a 4 ms row
// from the speed on the line: 1.2 % high); and the held-out machine's check
// on the other program.
TEST(RealLogs, ADeadTimeOfATickOfTheVelocityLoopIsFoundUnderASlowerPositionLoop) {
  for (const auto& [every, delay_ticks] : {std::pair{2, 1}, std::pair{2, 0}, std::pair{4, 2}, std::pair{4, 0}}) {
    SCOPED_TRACE(fmt::format("position loop {} ms, dead time {} ms", every, delay_ticks));
    truth::RunSpec sp = cascade_spec(1e-3);
    sp.cascade.position_every = every;
    sp.effects.delay_ticks = delay_ticks;
    const DataCalibration r =
        calibrate_on_two_programs(sp, fmt::format("tick_dead_time_{}_{}", every, delay_ticks));
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_TRUE(ax.identified) << ax.note;
    EXPECT_EQ(ax.law_inner_ticks, every) << ax.loop_source;
    EXPECT_FALSE(ax.logs_period_mean()) << ax.loop_source;
    expect_delay_kept(r, 1e-3 * delay_ticks);
    EXPECT_NEAR(ax.torque_lag_rows(), static_cast<double>(delay_ticks) / every, 1e-12) << ax.loop_source;
    AxisFromData at_lag = ax;  // the gains the delay is replayed with
    at_lag.gains = ax.gains_at_lag;
    expect_truth_gains(at_lag, sp);
    const double J_raw = sp.plant.J * 40.0 / sp.plant.rg;
    EXPECT_NEAR(ax.J, J_raw, (delay_ticks > 0 ? 0.01 : 0.015) * J_raw) << ax.torque_timing;
    expect_held_out_check(r);
  }
}

// Which rows load_run keeps of a log faster than its loop, on a made-up
// 1 kHz log whose x_vcmd_mm_s changes only on rows 2, 5, 8, ... (a 3 ms
// loop, phase 2): exactly those rows, 3 ms apart, with a note; the same
// where meta.json states 3 ms; the log's own rows kept beside them
// (MeasuredRun::log_rows: all 3000, and which row each kept one is, the
// rows the law and the drive are fitted on again). Kept as logged: a
// command that changes on every row, one that changes fewer than 100
// times, and a log whose meta states its own period.
TEST(RealLogs, TheRowsOfASlowerLoopsTicksAreFoundFromItsHeldOutput) {
  const auto write = [](const std::string& name, const std::string& period, int every, int rows) {
    const auto d = work(name);
    std::ofstream(d / "meta.json") << R"({"machine": null, "axes": ["x"], "sample_period_s": 0.001, )"
                                   << R"("controller_period_s": )" << period << "}";
    std::ofstream f(d / "trace.csv");
    f << "t_s,x_ref_mm,x_mm,x_vcmd_mm_s,x_torque_raw\n";
    double vcmd = 0.0;
    for (int k = 0; k < rows; ++k) {
      if (k % every == 2 % every) vcmd = 10.0 * std::sin(0.01 * k) + 0.001 * k;
      f << fmt::format("{:.3f},{:.6f},{:.6f},{:.6f},{:.6f}\n", 1e-3 * k, 0.5 * k * 1e-3, 0.5 * k * 1e-3 - 0.01, vcmd,
                       std::cos(0.02 * k));
    }
    return d;
  };
  for (const char* period : {"null", "0.003"}) {
    SCOPED_TRACE(period);
    const MeasuredRun held = load_run(write("held3", period, 3, 3000));
    EXPECT_EQ(held.log_rows_per_loop_period, 3u);
    EXPECT_NEAR(held.sample_period_s, 3e-3, 1e-12);
    ASSERT_EQ(held.trace.num_rows(), 1000u);
    const auto& t = held.trace.at("t_s");
    EXPECT_NEAR(t[0], 0.002, 1e-12);
    EXPECT_NEAR(t[999], 2.999, 1e-9);
    EXPECT_NEAR(held.trace.at("x_torque_raw")[1], std::cos(0.02 * 5), 1e-6);
    EXPECT_EQ(held.loop_period_seen_in, "x_vcmd_mm_s");
    ASSERT_FALSE(held.notes.empty());
    EXPECT_THAT(held.notes.back(), HasSubstr("x_vcmd_mm_s changes only on every 3rd row (100.0 % of the 1000 "
                                             "rows the loop's output changes on)"));
    EXPECT_THAT(held.notes.back(), HasSubstr("every 3rd from row 3"));
    // The log's own rows, beside: every row as read, and which each kept row is.
    ASSERT_TRUE(held.log_rows.has_value());
    EXPECT_EQ(held.log_rows->trace.num_rows(), 3000u);
    EXPECT_DOUBLE_EQ(held.log_rows->sample_period_s, 1e-3);
    ASSERT_EQ(held.log_rows->kept.size(), 1000u);
    for (std::size_t j : {std::size_t{0}, std::size_t{1}, std::size_t{999}}) {
      const std::size_t k = held.log_rows->kept[j];
      EXPECT_EQ(k, 3 * j + 2);
      EXPECT_DOUBLE_EQ(held.log_rows->trace.at("t_s")[k], t[j]);
      EXPECT_DOUBLE_EQ(held.log_rows->trace.at("x_torque_raw")[k], held.trace.at("x_torque_raw")[j]);
    }
  }
  // Gaps in the clock: the ticks fall on other rows of each part after a
  // gap. Rows 1500 to 1509 and row 2000 missing (a tick among them: 1502,
  // 1505, 1508 and 2000): the parts after the gaps start at rows 1510 and
  // 2001, whose ticks (k % 3 == 2) are their rows 1 and 2 (k = 1511, 2003).
  {
    const auto d = write("held_gaps", "null", 3, 3000);
    std::ifstream in(d / "trace.csv");
    std::vector<std::string> lines;
    for (std::string line; std::getline(in, line);) lines.push_back(line);
    in.close();
    std::ofstream out(d / "trace.csv");
    for (std::size_t i = 0; i < lines.size(); ++i) {
      const std::ptrdiff_t row = static_cast<std::ptrdiff_t>(i) - 1;
      if ((row >= 1500 && row < 1510) || row == 2000) continue;
      out << lines[i] << "\n";
    }
    out.close();
    const MeasuredRun gaps = load_run(d);
    EXPECT_EQ(gaps.log_rows_per_loop_period, 3u);
    const auto& t = gaps.trace.at("t_s");
    ASSERT_EQ(gaps.time_breaks.size(), 2u);
    // Every kept row is a tick of the made-up loop (its row k % 3 == 2).
    for (double tk : t) EXPECT_EQ(std::lround(tk * 1e3) % 3, 2) << tk;
    EXPECT_NEAR(t[gaps.time_breaks[0]], 1.511, 1e-9);
    EXPECT_NEAR(t[gaps.time_breaks[1]], 2.003, 1e-9);
    EXPECT_EQ(gaps.trace.num_rows(), 1000u - 3u - 1u);
  }
  const MeasuredRun every_row = load_run(write("held1", "null", 1, 3000));
  EXPECT_EQ(every_row.log_rows_per_loop_period, 1u);
  EXPECT_EQ(every_row.trace.num_rows(), 3000u);
  EXPECT_FALSE(every_row.log_rows.has_value());
  const MeasuredRun few = load_run(write("held_few", "null", 3, 240));  // 80 changes
  EXPECT_EQ(few.trace.num_rows(), 240u);
  const MeasuredRun own = load_run(write("held_own", "0.001", 3, 3000));
  EXPECT_EQ(own.trace.num_rows(), 3000u);
  EXPECT_DOUBLE_EQ(own.sample_period_s, 1e-3);
}

// A 1 kHz log of a cascade whose position loop runs every 2 ms (the
// velocity loop every 1 ms), the controller period not stated: the velocity
// command changes only on every second row. Taken as a 1 ms loop, the twin
// recomputed the command every row where the machine holds it. Oracles: the
// truth's structure, which the data shows exactly (2 ms, the rows of the
// loop's ticks, a velocity loop of 2 ticks a period); the truth's gains as
// for the 1 kHz loop (expect_truth_gains); the held-out machine's check on
// the other program; and `twin replay --machine` on the 1 kHz validation
// log giving the report's numbers. The same truth with meta.json stating
// 2 ms gives the same machine; a 1 ms loop logged at 1 kHz without the
// period stated is not read as slower.
TEST(RealLogs, APositionLoopSlowerThanItsLogIsReadFromTheHeldVelocityCommand) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  sp.cascade.position_every = 2;
  sp.period_in_meta = truth::RunSpec::PeriodInMeta::kNone;
  const DataCalibration r = calibrate_on_two_programs(sp, "held_vcmd");
  EXPECT_TRUE(has_note(r, "controller period 0.002 s: x_vcmd_mm_s changes only every 2nd row"));
  EXPECT_DOUBLE_EQ(r.final_machine.Ts_s, 2e-3);
  ASSERT_EQ(r.axis.size(), 1u);
  const AxisFromData& ax = r.axis[0];
  ASSERT_TRUE(ax.identified) << ax.note;
  EXPECT_EQ(ax.law_inner_ticks, 2) << ax.loop_source;
  expect_truth_gains(ax, sp);
  expect_held_out_check(r);
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const auto& e = r.validation_runs[0].calibrated.nrms;
  const auto yaml_dir = work("held_vcmd_yaml");
  io::write_file_atomic(yaml_dir / "machine.yaml", io::machine_to_yaml(r.final_machine, "test"));
  const MeasuredRun val = load_run(std::filesystem::temp_directory_path() / "twin_real_logs_test" / "held_vcmd_val");
  EXPECT_DOUBLE_EQ(val.sample_period_s, 2e-3);
  const RunErrors again =
      evaluate_machine_on_run(val, machine_for_run(val, (yaml_dir / "machine.yaml").string(), nullptr), nullptr, nullptr);
  for (const auto& [k, v] : e) {
    ASSERT_TRUE(again.calibrated.nrms.count(k)) << k;
    EXPECT_DOUBLE_EQ(again.calibrated.nrms.at(k), v) << k;
  }

  sp.period_in_meta = truth::RunSpec::PeriodInMeta::kLoop;
  const DataCalibration stated = calibrate_on_two_programs(sp, "held_vcmd_stated");
  EXPECT_TRUE(has_note(stated, "controller period 0.002 s from meta.json"));
  ASSERT_EQ(stated.axis.size(), 1u);
  EXPECT_DOUBLE_EQ(stated.axis[0].gains.Kv_per_s, ax.gains.Kv_per_s);
  EXPECT_DOUBLE_EQ(stated.validation_runs[0].calibrated.nrms.at("x_err_mm"), e.at("x_err_mm"));

  // A logger that samples the command before the loop updates it: each
  // new value shows a row after the tick. The P law fits the position a
  // row earlier, so the ticks are the rows before the changes and the
  // command is read a row on; the same machine's gains follow.
  sp.cascade.log_vcmd_before_update = true;
  sp.period_in_meta = truth::RunSpec::PeriodInMeta::kNone;
  const DataCalibration before = calibrate_on_two_programs(sp, "held_vcmd_before");
  EXPECT_TRUE(has_note(before, "shows each new value 1 row after the loop's tick"));
  EXPECT_TRUE(has_note(before, "controller period 0.002 s"));
  ASSERT_EQ(before.axis.size(), 1u);
  ASSERT_TRUE(before.axis[0].identified) << before.axis[0].note;
  expect_truth_gains(before.axis[0], sp);
  expect_held_out_check(before);
  sp.cascade.log_vcmd_before_update = false;

  sp.cascade.position_every = 1;
  sp.period_in_meta = truth::RunSpec::PeriodInMeta::kNone;
  const DataCalibration fast = calibrate_on_two_programs(sp, "held_vcmd_fast");
  EXPECT_TRUE(has_note(fast, "the log's own period 0.001 s is taken"));
  EXPECT_FALSE(has_note(fast, "changes only every"));
  EXPECT_DOUBLE_EQ(fast.final_machine.Ts_s, 1e-3);
}

// A 1 kHz cascade log whose positions, commanded and measured, are exported
// to 0.01 mm (a display's two decimals), with a Stribeck rise in the truth.
// An encoder does not round the command, so that is the log's rounding: the
// twin closes its loop on a fine encoder and rounds as the log. Taken as a
// 10 um encoder with the rows as the reference, the sweep's runs validated
// at 0.066 to 0.072 tracking and a torque error near 1. Oracles: the truth's
// Kv and kff (3 % and 0.012: the error, the speed and the command are
// low-passed for the fit, and Kv comes out 2.6 % low under this rounding);
// the held-out machine's check on the other program, whose floor here (the
// machine calibrated on the same runs unrounded, replayed on the rounded
// one) is 0.0062, so the check must also stay within twice that floor; and
// the torque below the regression's and under 0.2 (it was near 1).
TEST(RealLogs, PositionsExportedToTwoDecimalsAreTheLogsRounding) {
  const double Ts = 1e-3;
  truth::RunSpec sp = cascade_spec_with_stribeck(Ts);
  auto both = [&](const std::string& name, const std::vector<double>& ref) {
    sp.reference_mm = ref;
    const auto d = work(name);
    truth::write_truth_run(d, sp);
    MeasuredRun fine = load_run(d);
    MeasuredRun rounded = fine;
    for (const char* c : {"x_ref_mm", "x_mm"}) {
      auto& col = rounded.trace.columns[static_cast<std::size_t>(
          std::find(rounded.trace.names.begin(), rounded.trace.names.end(), c) - rounded.trace.names.begin())];
      for (double& x : col) x = std::round(x * 100.0) / 100.0;
    }
    return std::pair{fine, rounded};
  };
  const auto [fit, fit_r] = both("two_decimals_fit", program(Ts, 1.0, 24.0));
  const auto [val, val_r] = both("two_decimals_val", program(Ts, 1.6, 12.0));
  const DataCalibration r = calibrate_from_data({fit_r}, {val_r}, machine_for_run(fit_r, "", nullptr));
  EXPECT_TRUE(has_note(r, "the commanded positions are rounded alike"));
  EXPECT_DOUBLE_EQ(r.final_machine.encoder_resolution_mm, sp.resolution_mm);  // meta.json's
  ASSERT_EQ(r.axis.size(), 1u);
  EXPECT_NEAR(r.axis[0].gains.Kv_per_s, 45.0, 1.35);
  EXPECT_NEAR(r.axis[0].gains.kff, 0.6, 0.012);
  expect_held_out_check(r);
  const DataCalibration unrounded = calibrate_from_data({fit}, {}, machine_for_run(fit, "", nullptr));
  const RunErrors floor = evaluate_machine_on_run(val_r, unrounded.final_machine, nullptr, nullptr);
  ASSERT_EQ(r.validation_runs.size(), 1u);
  const auto& e = r.validation_runs[0].calibrated.nrms;
  EXPECT_LT(e.at("x_err_mm"), 2.0 * floor.calibrated.nrms.at("x_err_mm"));
  EXPECT_LT(e.at("x_torque_raw"), 0.2);
}

// The truth's current loop as a first-order lag of 0.5 and 2 ms (its logged
// torque is the lagged one), with a Stribeck rise the drive does not have,
// and a lag of 1 ms behind a dead time of 2 ms (a drive's sampling and its
// current loop together). Fitted as an instant current loop, Kvp came out 2 %
// and 22 % low, and a 2 ms lag was read as a delay of one row; fitted as a
// lag alone or a delay alone, the lag behind a dead time was read as a 3 ms
// delay and the other program tracked at 0.054 NRMS on the cascade sweep.
// Oracle: the truth's lag and the velocity loop's gains (the law is exact at
// the log's period, so 5 % on tau_i and Kvp and 10 % on Tn, as for the gains
// elsewhere), the truth's dead time as the delay kept and none where it has
// none, and the held-out machine's check on the other program.
TEST(RealLogs, ACurrentLoopLagIsIdentified) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  for (const auto& [tau_s, delay_ticks] : std::vector<std::pair<double, int>>{{0.0005, 0}, {0.002, 0}, {0.001, 2}}) {
    SCOPED_TRACE(fmt::format("lag {} s, dead time {} periods", tau_s, delay_ticks));
    sp.cascade.tau_i = tau_s;
    sp.effects.delay_ticks = delay_ticks;
    const DataCalibration r = calibrate_on_two_programs(sp, "lag");
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    EXPECT_NEAR(ax.gains.tau_i_s, tau_s, 0.05 * tau_s) << ax.loop_source;
    EXPECT_THAT(ax.loop_source, HasSubstr("a current loop lagging the law"));
    EXPECT_FALSE(ax.torque_command_logged) << ax.torque_command_choice;
    // In the loop, not the monitor's (ATorqueMonitorsLagIsKeptOutOfTheLoop).
    EXPECT_FALSE(ax.lag_in_monitor) << ax.loop_source;
    EXPECT_EQ(r.final_machine.axes[index(Axis::kX)].logged_torque_filter_s, 0.0);
    EXPECT_NEAR(r.final_machine.axes[index(Axis::kX)].loop.cascade.tau_i_s, tau_s, 0.05 * tau_s);
    expect_truth_gains(ax, sp);
    EXPECT_EQ(ax.torque_lag_samples, static_cast<std::size_t>(delay_ticks));
    expect_delay_kept(r, 1e-3 * delay_ticks);
    expect_held_out_check_behind(r, delay_ticks);
  }
}

// The truth's torque logged through a first-order low-pass of 1 and 2 ms
// that its loop does not see (a drive's smoothed torque monitor), with a
// Stribeck rise the drive does not have and an instant current loop. The
// law fits the log with that lag, as it fits a current loop's: put in the
// twin's loop, a 2 ms lag made the cascade sweep's run without an effect
// track the other program at 0.026 (0.0028 without it) and its torque at
// 0.41, and 13 of the sweep's 14 runs of one magnitude missed 0.01. Only the
// motion tells the two apart. Without the motor's speed (the speed taken
// from the position through its low-pass) the lag is read through that
// filter: with the Stribeck rise and a 0.5 um encoder as a first-order lag;
// with no effect and a 1 um encoder (the sweep's) it fits the law no better
// than a 1 ms dead time, so it was read as a delay, which the replay
// refused, and the gains fitted without a lag stayed: the other program
// tracked at 0.016 on the fitting runs' held-out rows (0.0027 now), and the
// sweep's runs at 0.019 to 0.025. Oracles: the truth's filter as the law's
// lag (5 %, as tau_i in ACurrentLoopLagIsIdentified, which checks the other
// way round), the final machine's loop without it and its logged channel
// through it, the truth's gains (expect_truth_gains), no delay kept, and the
// held-out machine's check on the other program.
TEST(RealLogs, ATorqueMonitorsLagIsKeptOutOfTheLoop) {
  struct Case {
    double filter_s;
    bool motor_speed, stribeck;
  };
  for (const auto& [filter_s, motor_speed, stribeck] :
       std::vector<Case>{{0.001, true, true}, {0.002, true, true}, {0.002, false, true}, {0.002, false, false}}) {
    SCOPED_TRACE(fmt::format("monitor lag {} s, motor speed {}, {}", filter_s,
                             motor_speed ? "logged" : "not logged", stribeck ? "a Stribeck rise" : "no effect"));
    truth::RunSpec sp = stribeck ? cascade_spec_with_stribeck(1e-3) : cascade_spec(1e-3);
    if (!stribeck) sp.resolution_mm = 0.001;  // the sweep's encoder
    sp.cascade.log_torque_filter_s = filter_s;
    sp.cascade.log_motor_speed = motor_speed;
    const DataCalibration r = calibrate_on_two_programs(sp, motor_speed ? "monitor" : "monitor_no_speed");
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    EXPECT_TRUE(ax.lag_in_monitor) << ax.loop_source;
    EXPECT_THAT(ax.loop_source, HasSubstr("outside the loop, in the logged x_torque_raw"));
    // Read as a dead time first, then placed in the monitor (place_law_dead_time).
    if (!stribeck) {
      EXPECT_THAT(ax.loop_source, HasSubstr("the law's lag is outside the loop"));
    }
    EXPECT_NEAR(ax.gains.tau_i_s, filter_s, 0.05 * filter_s) << ax.loop_source;
    const sim::AxisDefinition& def = r.final_machine.axes[index(Axis::kX)];
    EXPECT_EQ(def.loop.cascade.tau_i_s, 0.0);
    EXPECT_NEAR(def.logged_torque_filter_s, filter_s, 0.05 * filter_s);
    expect_delay_kept(r, 0.0);
    EXPECT_FALSE(ax.torque_command_logged) << ax.torque_command_choice;
    expect_truth_gains(ax, sp);
    expect_held_out_check(r);
  }
}

// The truth's torque logged as its velocity loop's command, the current
// loop's input (as many drives trace it), with its current loop a lag of 1
// and 2 ms and a lag of 1 ms behind a dead time of 2 ms, and a Stribeck rise
// the drive does not have. The law fits the logged torque with no lag; the
// motion answers to it through the lag and the dead time. Read as the motor's
// torque (the twin's current loop ideal), the other program tracked at 0.007
// and its torque at 0.12 on the cascade sweep's run without an effect, and 19
// of its 32 runs named an effect wrong. Oracles: the truth's lag (10 %: it is
// read from the drive's fit, whose residual the Stribeck rise dominates; 5.2
// and 2.6 % low at 1 and 2 ms) and gains (expect_truth_gains), its dead time
// as the delay kept and none where it has none, and the held-out machine's
// check on the other program; the same
// truth logging the motor's torque is not taken for a command
// (ACurrentLoopLagIsIdentified). A lag of 0.5 ms moves the torque by less
// than the Stribeck rise's misfit (the drive fits the motion 0.42 ms behind,
// residual 0.958 against 1.01, and replays the held-out rows' torque at
// 0.3125 against 0.3081 read as the motor's): either reading must pass the
// held-out check there, and the report's loop line says which was taken.
TEST(RealLogs, ATorqueCommandLoggedBeforeTheCurrentLoopIsFound) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  sp.cascade.log_torque_command = true;
  for (const auto& [tau_s, delay_ticks] :
       std::vector<std::pair<double, int>>{{0.001, 0}, {0.002, 0}, {0.001, 2}, {0.0005, 0}}) {
    SCOPED_TRACE(fmt::format("lag {} s, dead time {} periods", tau_s, delay_ticks));
    sp.cascade.tau_i = tau_s;
    sp.effects.delay_ticks = delay_ticks;
    const DataCalibration r = calibrate_on_two_programs(sp, "command");
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_EQ(r.validation_runs.size(), 1u);
    const auto& e = r.validation_runs[0].calibrated.nrms;
    std::printf("  lag %g s, dead time %d: command %s, tau_i %.4g s, validation tracking %.4f, torque %.4f "
                "(regression %.4f)\n",
                tau_s, delay_ticks, ax.torque_command_logged ? "yes" : "no", ax.gains.tau_i_s, e.at("x_err_mm"),
                e.at("x_torque_raw"), r.validation_runs[0].regression.nrms.at("x_torque_raw"));
    if (tau_s < 0.001) {
      expect_held_out_check(r);
      // Either reading, the report's loop line says which and why.
      EXPECT_THAT(ax.loop_source, HasSubstr(ax.torque_command_logged ? "the logged torque is the loop's command"
                                                                     : "the logged torque is taken as the motor's"));
      continue;
    }
    EXPECT_TRUE(ax.torque_command_logged) << ax.loop_source << "\n" << ax.torque_command_choice;
    EXPECT_EQ(r.final_machine.axes[index(Axis::kX)].torque_command_logged, 1.0);
    EXPECT_NEAR(ax.gains.tau_i_s, tau_s, 0.1 * tau_s) << ax.loop_source;
    expect_truth_gains(ax, sp);
    EXPECT_EQ(ax.torque_lag_samples, static_cast<std::size_t>(delay_ticks));
    expect_delay_kept(r, 1e-3 * delay_ticks);
    expect_held_out_check_behind(r, delay_ticks);
  }
}

// A channel logged one row after the motion it belongs to (a logger that
// samples some of the drive's signals a cycle late), on the truth with a
// Stribeck rise the drive does not have: the torque, without and with a 2 ms
// delay in the drive (whose logged torque is the delayed one), and the speed.
// The velocity loop's law fits such a torque best a row late either way, so
// the skew was read as a delay: on the cascade sweep the other program's
// tracking went to 0.010 to 0.018 NRMS, and 0.34 where the drive has a delay
// too. A delay in the drive delays the torque and the motion together; only
// the log's timing puts the torque behind the speed's change. A speed a row
// late put every law across the skew (tracking 0.024 to 0.12). Oracles: the
// note, from load_run, on the skewed runs and not on the same runs logged in
// line; the truth's gains (expect_truth_gains) and the held-out machine's
// check; the truth's delay, 2 ms to the 1 ms row, kept where the drive has
// one (the law's gains then those fitted at its lag), and none kept where it
// has none.
TEST(RealLogs, AChannelLoggedARowLateIsReadBackInLine) {
  truth::RunSpec sp = cascade_spec_with_stribeck(1e-3);
  // The truth's run of `ref` with the column `late_column` logged a row late.
  const auto late = [&](const std::string& name, const std::vector<double>& ref, const std::string& late_column) {
    sp.reference_mm = ref;
    const auto whole = work(name + "_in_line");
    truth::write_truth_run(whole, sp);
    for (const auto& n : load_run(whole).notes)
      EXPECT_THAT(n, ::testing::Not(HasSubstr("after the motion it belongs")));
    std::size_t field = 0;
    std::string previous;
    return rewritten_run(whole, name, [&](std::ptrdiff_t row, std::string& line) {
      std::vector<std::string> cells;
      std::stringstream in(line);
      for (std::string c; std::getline(in, c, ',');) cells.push_back(c);
      if (row < 0) {
        field = static_cast<std::size_t>(std::find(cells.begin(), cells.end(), late_column) - cells.begin());
        EXPECT_LT(field, cells.size()) << late_column;
        return true;
      }
      const std::string logged = cells.at(field);
      if (row > 0) cells[field] = previous;
      previous = logged;
      line = fmt::format("{}", fmt::join(cells, ","));
      return true;
    });
  };
  for (const auto& [late_column, delay_ticks] :
       std::vector<std::pair<std::string, int>>{{"x_torque_raw", 0}, {"x_torque_raw", 2}, {"x_v_mm_s", 0}}) {
    SCOPED_TRACE(late_column + ", delay " + std::to_string(delay_ticks));
    sp.effects.delay_ticks = delay_ticks;
    const MeasuredRun fit = late("late_fit", program(sp.Ts_s, 1.0, 24.0), late_column);
    const MeasuredRun val = late("late_val", program(sp.Ts_s, 1.6, 12.0), late_column);
    const DataCalibration r = calibrate_from_data({fit}, {val}, machine_for_run(fit, "", nullptr));
    EXPECT_TRUE(has_note(r, late_column + " is logged 1 row after the motion it belongs to"));
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_TRUE(ax.identified) << ax.note;
    // With a delay, the law's gains are those fitted at the delay's lag.
    EXPECT_EQ(ax.torque_lag_samples, static_cast<std::size_t>(delay_ticks));
    AxisFromData at_lag = ax;
    at_lag.gains = ax.gains_at_lag;
    expect_truth_gains(at_lag, sp);
    expect_held_out_check(r);
    expect_delay_kept(r, 1e-3 * delay_ticks);
  }
}

// Logs whose clock has gaps: the 1 kHz runs of CascadeAtOneKilohertzWithRawTorque,
// each with a block of rows cut out while the axis moves (the logger paused)
// and single rows dropped at other places where it moves (one in the fitting
// run's held-out part). Taken as uniform, a dropped row would be a sample in
// which the command moves twice as far; replayed through a gap, the loop
// would follow a command that jumps; replayed from rest after it, the drive
// would run a transient under a moving command. Each part between gaps is a
// segment replayed from its own start in the motion it begins in, so the
// calibration must find what it finds on the whole log: the same tolerances
// as that test (the gains from the logged loop signals to 1 %, the velocity
// loop to 5 and 10 %), and the following error within 1 % NRMS on the
// other program and on the fitting run's held-out part, gaps and all.
TEST(RealLogs, GapsInTheClockAreSegments) {
  const double Ts = 1e-3;
  // position_every 2: the same with the position loop every 2 ms and no
  // period stated; the rows of its ticks are found in each part between
  // gaps (their phase moves where a gap drops an odd number of rows), and
  // the calibration must find the same at the loop's 2 ms.
  for (const int position_every : {1, 2}) {
    SCOPED_TRACE(position_every);
    truth::RunSpec sp = cascade_spec(Ts);
    sp.cascade.position_every = position_every;
    if (position_every > 1) sp.period_in_meta = truth::RunSpec::PeriodInMeta::kNone;
    const std::string tag = position_every > 1 ? "gaps2" : "gaps";
    // Writes the truth run of `ref` with rows left out: `block` rows from the
    // first row at or after block_from where the command moves faster than
    // 5 mm/s, and one row at each such place after `singles`.
    auto gappy_run = [&](const std::string& name, const std::vector<double>& ref, std::size_t block_from,
                         std::size_t block, const std::vector<std::size_t>& singles) {
      sp.reference_mm = ref;
      const auto whole = work(name + "_whole");
      truth::write_truth_run(whole, sp);
      auto moving_from = [&](std::size_t k) {
        while (k + 1 < ref.size() && std::abs(ref[k + 1] - ref[k]) < 5.0 * Ts) ++k;
        return k;
      };
      std::vector<std::size_t> dropped;
      const std::size_t cut = moving_from(block_from);
      for (std::size_t k = cut; k < cut + block; ++k) dropped.push_back(k);
      for (std::size_t from : singles) dropped.push_back(moving_from(from));
      const MeasuredRun run = rewritten_run(whole, name, [&](std::ptrdiff_t row, std::string&) {
        return row < 0 || std::find(dropped.begin(), dropped.end(), static_cast<std::size_t>(row)) == dropped.end();
      });
      return std::make_pair(run, cut);
    };
    const auto [run, cut] = gappy_run(tag + "_fit", program(Ts, 1.0, 24.0), 4000, 700, {9000, 12000, 20000});
    const MeasuredRun val = gappy_run(tag + "_val", program(Ts, 1.6, 12.0), 3000, 300, {7000, 9500}).first;

    EXPECT_NEAR(run.sample_period_s, Ts * position_every, 1e-9);
    ASSERT_EQ(run.time_breaks.size(), 4u);
    if (position_every == 1) {
      EXPECT_EQ(run.time_breaks[0], cut);
    } else {
      EXPECT_NEAR(run.trace.at("t_s")[run.time_breaks[0]] - run.trace.at("t_s")[run.time_breaks[0] - 1],
                  Ts * (700 + position_every), Ts * position_every + 1e-9);
      bool ticks = false;
      for (const auto& n : run.notes) ticks = ticks || n.find("after the gap from row") != std::string::npos;
      EXPECT_TRUE(ticks);
    }
    bool said = false;
    for (const auto& n : run.notes) said = said || n.find("t_s has 4 gaps") != std::string::npos;
    EXPECT_TRUE(said);
    const auto segs = find_segments(run, 0.0, std::nullopt, nullptr);
    ASSERT_EQ(segs.size(), 5u);
    for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(segs[i + 1].begin, run.time_breaks[i]);
    ASSERT_EQ(val.time_breaks.size(), 3u);

    const DataCalibration r = calibrate_from_data({run}, {val}, machine_for_run(run, "", nullptr));
    EXPECT_DOUBLE_EQ(r.final_machine.Ts_s, Ts * position_every);
    ASSERT_EQ(r.axis.size(), 1u);
    const AxisFromData& ax = r.axis[0];
    ASSERT_TRUE(ax.identified) << ax.note;
    expect_truth_gains(ax, sp);
    expect_held_out_check(r);
    ASSERT_EQ(r.fit_runs.size(), 1u);
    EXPECT_LT(r.fit_runs[0].calibrated.nrms.at("x_err_mm"), 0.01);
    // The twin's own trace holds every logged row, at its logged time.
    EXPECT_EQ(r.replay_after.t_s, run.trace.at("t_s"));
  }
}

// One Coulomb level where the log does not support two. The truth's
// friction is the same both ways (0.2 N m, no load), so one level is its
// structure. The fitting part moves + at 10 and 11 mm/s and - at 40 and
// 42: a level per direction leaves the viscous slope to speed spans of 1 and
// 2 mm/s, under the noise of positions logged every 0.1 s to 0.1 mm (that
// fit comes out with a negative slope, set to 0, and levels 2.3 and 7.9 A
// against the truth's 0.42 A); one level ties the midpoint of the moving
// levels to the rest level and takes the slope from 10 against 40 mm/s. The
// held-out part moves + at 45 and - at 12 mm/s. Checked against the truth's
// structure: one level is taken here, and (CascadeAtOneKilohertzWithRawTorque)
// two where the truth's levels differ.
TEST(RealLogs, OneCoulombLevelWhereTheLogDoesNotSupportTwo) {
  const double Ts = 1e-3;
  truth::RunSpec sp = cascade_spec(Ts);
  sp.plant.Tc_pos = sp.plant.Tc_neg = 0.2;
  sp.effects.load_Nm = 0.0;
  sp.cascade.raw_per_Nm = 0.0;
  sp.cascade.log_velocities = false;
  sp.cascade.kff = 0.0;
  sp.log_every = 100;
  sp.log_significant_figures = 3;
  sp.current_noise_A = 0.05;
  sp.reference_mm = truth::moves_program(
      Ts, {10.0, -40.0, 11.0, -42.0, 10.0, -40.0, 11.0, -42.0, 10.0, -40.0, 11.0, -42.0, 45.0, -12.0, 45.0, -12.0, 45.0,
           -12.0, 45.0, -12.0},
      40.0);
  const auto d = work("one_level");
  truth::write_truth_run(d, sp);
  const MeasuredRun run = load_run(d);
  const DataCalibration r = calibrate_from_data({run}, {}, machine_for_run(run, "", nullptr));
  ASSERT_EQ(r.axis.size(), 1u);
  const AxisFromData& ax = r.axis[0];
  ASSERT_TRUE(ax.identified) << ax.note;
  EXPECT_TRUE(ax.one_coulomb_level) << ax.coulomb_choice;
  EXPECT_DOUBLE_EQ(ax.Tc_pos, ax.Tc_neg);
  EXPECT_THAT(ax.coulomb_choice, HasSubstr("one Coulomb level for both directions"));
  const auto j = data_calibration_report_json(r);
  EXPECT_EQ(j["parameters_identified"]["x"]["coulomb_levels"], 1);
  EXPECT_EQ(j["parameters_identified"]["x"]["Tc_pos"], j["parameters_identified"]["x"]["Tc_neg"]);
}

}  // namespace
}  // namespace twin::analysis
