#pragma once
/// The part-program subset a 3-axis pocket program uses: G0 G1 G2 G3 (I J K
/// and R), G4 (dwell, P seconds), G17, G20 G21, G90 G91, G61 (exact path), G61.1
/// (exact stop) and G64 (with P),
/// F, S, M3 M4 M5 M30 (and M2), comments ( ... ) and ;, N numbers, % lines.
/// Every unknown word or malformed line is a ConfigError "file:line: ..."
/// quoting at most a short escaped excerpt of the line. G and M codes beyond
/// 1000, N and T that are not whole numbers in range, S beyond 200000 rpm and
/// a program without a single move or dwell are errors.
/// Accepted without effect: T (tool select; the twin's tool comes from the
/// scenario), M8 M9 (coolant), G40 G49 G80 G94 G54 (cancel/identity states).
/// Units: G20 scales X Y Z I J K R F and G64 P by 25.4; G4 P is seconds.
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "twin/core/axis.hpp"

namespace twin::controller {

enum class MotionKind { kRapid, kLinear, kArcCw, kArcCcw, kDwell };

/// One motion of the program, in mm, absolute machine coordinates.
struct Block {
  int line{0};                         ///< 1-based source line
  MotionKind kind{MotionKind::kLinear};
  AxisArray<double> start_mm{};
  AxisArray<double> end_mm{};
  AxisArray<double> center_mm{};       ///< arcs: centre (XY plane, G17); z of center unused
  double feed_mm_per_min{0.0};         ///< programmed feed (rapid: the machine's rapid rate)
  double spindle_rpm{0.0};             ///< signed: M3 > 0, M4 < 0, M5 0
  bool exact_stop{false};              ///< G61.1 in force: stop at the end of this block
  bool exact_path{false};              ///< G61 in force: no blend at the end of this block (stop at a corner)
  double blend_tolerance_mm{0.0};      ///< G64 P in force (0: the machine's default)
  double dwell_s{0.0};                 ///< G4
};

struct Program {
  std::string source_name;             ///< file name used in messages
  std::vector<Block> blocks;
  double spindle_rpm_at_end{0.0};      ///< spindle in force after the last line (M2/M30 stop it)
};

/// Parses `text`. `start_mm` is where the machine is before the first block.
/// `rapid_mm_per_min` is the feed recorded for G0 blocks.
Program parse_gcode(std::string_view text, std::string_view source_name,
                    const AxisArray<double>& start_mm, double rapid_mm_per_min);
/// Largest G-code file load_gcode reads.
inline constexpr std::uintmax_t kMaxProgramBytes = std::uintmax_t{256} << 20;
/// Reads and parses a regular file of at most kMaxProgramBytes; IoError if
/// it cannot be read (a directory, FIFO or device, too large).
Program load_gcode(const std::string& path, const AxisArray<double>& start_mm,
                   double rapid_mm_per_min);

}  // namespace twin::controller
