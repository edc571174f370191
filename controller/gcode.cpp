#include "controller/gcode.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/text.hpp"
#include "twin/core/units.hpp"

namespace twin::controller {
namespace {

/// Arc end radius may differ from the start radius by this much (absolute)
/// or by this fraction of the radius, whichever is larger.
constexpr double kArcRadiusTolerance_mm = 0.002;
constexpr double kArcRadiusTolerance_rel = 1e-3;
/// G and M codes are small integers (G0..G99.9, M0..M999): anything beyond
/// is refused before it is rounded to an int.
constexpr double kMaxCode = 1000.0;
/// N (line numbers) and T (tool numbers) are non-negative integers below these.
constexpr double kMaxLineNumber = 1e9;
constexpr double kMaxToolNumber = 1e6;
/// The fastest spindles on milling machines turn about 10^5 rpm; S beyond
/// this is a typing error (or an attack), not a speed.
constexpr double kMaxSpindle_rpm = 200000.0;
/// Error messages quote at most this many characters of the offending text.
constexpr std::size_t kExcerptChars = 40;

/// A short printable excerpt of the offending text (twin/core/text.hpp).
std::string excerpt(std::string_view text) { return printable_excerpt(text, kExcerptChars, ExcerptBytes::kAscii); }

struct Word {
  char letter{};
  double value{0.0};
  std::string text;  // as written, for messages
};

/// One program line: the words it holds, at most one per letter except G/M.
struct LineWords {
  std::vector<double> g;
  std::vector<double> m;
  std::array<std::optional<double>, 26> by_letter{};
  std::array<std::string, 26> text_by_letter{};
  bool has(char c) const { return by_letter[static_cast<std::size_t>(c - 'A')].has_value(); }
  double get(char c) const { return *by_letter[static_cast<std::size_t>(c - 'A')]; }
};

class Parser {
 public:
  Parser(std::string_view source_name, const AxisArray<double>& start_mm, double rapid_mm_per_min)
      : name_(source_name), pos_mm_(start_mm), rapid_mm_per_min_(rapid_mm_per_min) {}

  Program run(std::string_view text) {
    Program program;
    program.source_name = std::string(name_);
    std::size_t begin = 0;
    line_ = 0;
    while (begin <= text.size() && !ended_) {
      std::size_t end = text.find('\n', begin);
      if (end == std::string_view::npos) end = text.size();
      ++line_;
      std::string_view raw = text.substr(begin, end - begin);
      if (!raw.empty() && raw.back() == '\r') raw.remove_suffix(1);
      parse_line(raw, program);
      if (end == text.size()) break;
      begin = end + 1;
    }
    if (program.blocks.empty()) {
      // The last line read: where M2/M30 ended the program, else the text's last line.
      const auto newlines = static_cast<int>(std::count(text.begin(), text.end(), '\n'));
      const int last = ended_ ? line_ : std::max(1, newlines + (!text.empty() && text.back() != '\n' ? 1 : 0));
      throw ConfigError(fmt::format("{}:{}: the program holds no move and no dwell (empty, or only comments, % and "
                                    "settings)",
                                    name_, last));
    }
    program.spindle_rpm_at_end = spindle_rpm();
    return program;
  }

 private:
  [[noreturn]] void fail(const std::string& what, std::string_view word) const {
    throw ConfigError(fmt::format("{}:{}: {} ({})", name_, line_, what, excerpt(word)));
  }

  /// Removes comments and blanks; returns the upper-cased word text.
  std::string clean(std::string_view raw) const {
    std::string out;
    bool in_paren = false;
    for (char c : raw) {
      if (in_paren) {
        if (c == ')') in_paren = false;
        continue;
      }
      if (c == '(') {
        in_paren = true;
        continue;
      }
      if (c == ')') fail("closing parenthesis without opening one", raw);
      if (c == ';') break;
      if (std::isspace(static_cast<unsigned char>(c))) continue;
      out.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
    }
    if (in_paren) fail("comment not closed", raw);
    return out;
  }

  /// Strict number: [+-] digits [. digits] or [+-] . digits.
  double parse_number(std::string_view s, std::string_view word) const {
    std::size_t i = 0;
    if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
    std::size_t digits = 0;
    bool dot = false;
    for (; i < s.size(); ++i) {
      if (std::isdigit(static_cast<unsigned char>(s[i]))) {
        ++digits;
      } else if (s[i] == '.' && !dot) {
        dot = true;
      } else {
        fail("malformed number", word);
      }
    }
    if (digits == 0) fail("malformed number", word);
    std::string copy(s);
    std::size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(copy, &used);
    } catch (const std::exception&) {
      fail("malformed number", word);
    }
    if (used != copy.size() || !std::isfinite(v)) fail("malformed number", word);
    return v;
  }

  LineWords split_words(const std::string& s) const {
    LineWords w;
    std::size_t i = 0;
    while (i < s.size()) {
      const char letter = s[i];
      if (letter < 'A' || letter > 'Z') fail("expected a letter", s.substr(i));
      std::size_t j = i + 1;
      while (j < s.size() && !(s[j] >= 'A' && s[j] <= 'Z')) ++j;
      const std::string word = s.substr(i, j - i);
      const double v = parse_number(std::string_view(word).substr(1), word);
      if (letter == 'G') {
        w.g.push_back(v);
      } else if (letter == 'M') {
        w.m.push_back(v);
      } else {
        const auto idx = static_cast<std::size_t>(letter - 'A');
        if (w.by_letter[idx].has_value()) fail(fmt::format("word {} given twice", letter), word);
        w.by_letter[idx] = v;
        w.text_by_letter[idx] = word;
      }
      i = j;
    }
    return w;
  }

  double spindle_rpm() const { return spindle_dir_ * spindle_speed_rpm_; }

  /// What a line's G codes ask of it beyond the modal state they set.
  struct LineModes {
    std::optional<MotionKind> motion;
    bool dwell{false};
    bool set_g64{false};
  };

  /// Refuses words of a letter the twin does not know.
  void check_letters(const LineWords& w) const {
    static constexpr std::string_view kSupportedLetters = "FIJKNPRSTXYZ";
    for (std::size_t idx = 0; idx < 26; ++idx) {
      if (!w.by_letter[idx].has_value()) continue;
      if (kSupportedLetters.find(static_cast<char>('A' + idx)) == std::string_view::npos)
        fail("unsupported word", w.text_by_letter[idx]);
    }
  }

  /// G code g (G0 ... G99.9): a motion or dwell of this line, or a modal setting.
  void apply_g_code(double g, LineModes& line) {
    const std::string word = fmt::format("G{}", g);
    if (!(std::abs(g) < kMaxCode)) fail("unknown G code", word);
    const double gr = std::round(g * 10.0) / 10.0;
    if (std::abs(g - gr) > 1e-9) fail("unknown G code", word);
    const int code10 = static_cast<int>(std::lround(gr * 10.0));
    auto set_motion = [&](MotionKind k) {
      if (line.motion || line.dwell) fail("two motion codes on one line", word);
      line.motion = k;
    };
    switch (code10) {
      case 0: set_motion(MotionKind::kRapid); break;
      case 10: set_motion(MotionKind::kLinear); break;
      case 20: set_motion(MotionKind::kArcCw); break;
      case 30: set_motion(MotionKind::kArcCcw); break;
      case 40:
        if (line.motion || line.dwell) fail("two motion codes on one line", word);
        line.dwell = true;
        break;
      case 170: break;
      case 180:
      case 190: fail("only the XY plane (G17) is supported", word);
      case 200: mm_per_unit_ = kMmPerInch; break;
      case 210: mm_per_unit_ = 1.0; break;
      case 900: incremental_ = false; break;
      case 910: incremental_ = true; break;
      case 610:  // exact path (LinuxCNC): no blending, tangent junctions pass
        exact_path_ = true;
        exact_stop_ = false;
        break;
      case 611:  // exact stop (LinuxCNC G61.1, Fanuc G61): stop after every block
        exact_stop_ = true;
        exact_path_ = false;
        break;
      case 640:
        exact_stop_ = false;
        exact_path_ = false;
        line.set_g64 = true;
        break;
      case 400:  // cutter compensation off: it is never on
      case 490:  // tool length offset cancel: none is applied
      case 540:  // first work offset: identity in the twin
      case 800:  // canned cycle cancel: none is supported
      case 940:  // feed per minute: the only feed mode
        break;
      default: fail("unknown G code", word);
    }
  }

  /// The line's M codes; true when one of them ends the program.
  bool apply_m_codes(const LineWords& w) {
    bool program_end = false;
    for (double m : w.m) {
      const std::string word = fmt::format("M{}", m);
      if (!(std::abs(m) < kMaxCode) || m != std::round(m)) fail("unknown M code", word);
      switch (static_cast<int>(m)) {
        case 3: spindle_dir_ = 1.0; break;
        case 4: spindle_dir_ = -1.0; break;
        case 5: spindle_dir_ = 0.0; break;
        case 2:
        case 30: program_end = true; break;
        case 8:
        case 9: break;  // coolant: no effect on the twin
        default: fail("unknown M code", word);
      }
    }
    return program_end;
  }

  /// F, N, T and S words.
  void apply_values(const LineWords& w) {
    if (w.has('F')) {
      const double f = w.get('F');
      if (!(f > 0.0)) fail("feed must be > 0", w.text_by_letter['F' - 'A']);
      feed_mm_per_min_ = f * mm_per_unit_;
    }
    for (const auto& [letter, max] : {std::pair{'N', kMaxLineNumber}, std::pair{'T', kMaxToolNumber}}) {
      if (!w.has(letter)) continue;
      const double v = w.get(letter);
      if (!(v >= 0.0 && v < max) || v != std::round(v))
        fail(fmt::format("{} must be a whole number in [0, {:.0f})", letter, max),
             w.text_by_letter[static_cast<std::size_t>(letter - 'A')]);
    }
    if (w.has('S')) {
      const double sp = w.get('S');
      if (sp < 0.0) fail("spindle speed must be >= 0", w.text_by_letter['S' - 'A']);
      if (sp > kMaxSpindle_rpm)
        fail(fmt::format("spindle speed beyond {:.0f} rpm", kMaxSpindle_rpm), w.text_by_letter['S' - 'A']);
      spindle_speed_rpm_ = sp;
    }
  }

  /// P: a dwell's seconds (G4) or a blend tolerance (G64).
  void apply_p(const LineWords& w, const LineModes& line) {
    if (w.has('P')) {
      const double p = w.get('P');
      const std::string& word = w.text_by_letter['P' - 'A'];
      if (line.dwell) {
        if (p < 0.0) fail("dwell must be >= 0", word);
      } else if (line.set_g64) {
        if (p < 0.0) fail("blend tolerance must be >= 0", word);
        blend_tolerance_mm_ = p * mm_per_unit_;
      } else {
        fail("P without G4 or G64", word);
      }
    } else if (line.set_g64) {
      blend_tolerance_mm_ = 0.0;
    }
    if (line.dwell && !w.has('P')) fail("G4 needs P (seconds)", "G4");
  }

  /// A block at the current position with the current modal settings.
  Block block_here() const {
    Block base;
    base.line = line_;
    base.start_mm = pos_mm_;
    base.end_mm = pos_mm_;
    base.center_mm = pos_mm_;
    base.spindle_rpm = spindle_rpm();
    base.exact_stop = exact_stop_;
    base.exact_path = exact_path_;
    base.blend_tolerance_mm = blend_tolerance_mm_;
    return base;
  }

  void parse_line(std::string_view raw, Program& program) {
    std::string s = clean(raw);
    if (s.empty()) return;
    if (s.front() == '%') return;
    const LineWords w = split_words(s);
    check_letters(w);
    LineModes line;
    for (double g : w.g) apply_g_code(g, line);
    const bool program_end = apply_m_codes(w);
    apply_values(w);
    apply_p(w, line);

    if (line.motion) motion_ = line.motion;
    const bool has_axis = w.has('X') || w.has('Y') || w.has('Z');
    const bool has_arc_word = w.has('I') || w.has('J') || w.has('K') || w.has('R');
    Block base = block_here();
    if (line.dwell) {
      if (has_axis || has_arc_word) fail("G4 takes no axis or arc words", s);
      base.kind = MotionKind::kDwell;
      base.dwell_s = w.get('P');
      program.blocks.push_back(base);
    } else if (has_axis || has_arc_word) {
      if (!motion_) fail("axis words without a motion mode", s);
      motion_block(*motion_, w, base, program);
    }
    if (program_end) {
      spindle_dir_ = 0.0;
      ended_ = true;
    }
  }

  void motion_block(MotionKind kind, const LineWords& w, Block b, Program& program) {
    b.kind = kind;
    static constexpr std::array<char, kNumAxes> kAxisLetters{'X', 'Y', 'Z'};
    for (std::size_t a = 0; a < kNumAxes; ++a) {
      if (!w.has(kAxisLetters[a])) continue;
      const double v_mm = w.get(kAxisLetters[a]) * mm_per_unit_;
      b.end_mm[a] = incremental_ ? pos_mm_[a] + v_mm : v_mm;
    }
    const bool is_arc = kind == MotionKind::kArcCw || kind == MotionKind::kArcCcw;
    if (!is_arc && (w.has('I') || w.has('J') || w.has('K') || w.has('R')))
      fail("arc words on a straight move", w.has('R') ? w.text_by_letter['R' - 'A'] : "I/J/K");
    if (kind == MotionKind::kRapid) {
      b.feed_mm_per_min = rapid_mm_per_min_;
    } else {
      if (!(feed_mm_per_min_ > 0.0)) fail("feed move with no F in force", fmt::format("G{}", static_cast<int>(kind)));
      b.feed_mm_per_min = feed_mm_per_min_;
    }
    if (is_arc) arc_center(w, b);
    program.blocks.push_back(b);
    pos_mm_ = b.end_mm;
  }

  void arc_center(const LineWords& w, Block& b) const {
    const double x0 = b.start_mm[0], y0 = b.start_mm[1];
    const double x1 = b.end_mm[0], y1 = b.end_mm[1];
    b.center_mm[2] = b.start_mm[2];
    if (w.has('R')) {
      const std::string& word = w.text_by_letter['R' - 'A'];
      if (w.has('I') || w.has('J')) fail("arc with both R and I/J", word);
      const double r = w.get('R') * mm_per_unit_;
      const double dx = x1 - x0, dy = y1 - y0;
      const double chord = std::hypot(dx, dy);
      if (!(std::abs(r) > 0.0)) fail("arc radius must not be 0", word);
      if (chord < 1e-9) fail("R arc with the same start and end point is impossible", word);
      const double half = 0.5 * chord;
      if (half > std::abs(r) * (1.0 + 1e-9) + 1e-9)
        fail(fmt::format("R arc impossible: chord {:.6g} mm longer than the diameter", chord), word);
      const double h = std::sqrt(std::max(0.0, r * r - half * half));
      // Left normal of the chord; a counter-clockwise short arc has its centre on the left.
      const double nx = -dy / chord, ny = dx / chord;
      double side = (b.kind == MotionKind::kArcCcw) ? 1.0 : -1.0;
      if (r < 0.0) side = -side;
      b.center_mm[0] = x0 + 0.5 * dx + side * h * nx;
      b.center_mm[1] = y0 + 0.5 * dy + side * h * ny;
    } else {
      if (!(w.has('I') || w.has('J'))) fail("arc without I/J or R", "G2/G3");
      const double i = w.has('I') ? w.get('I') * mm_per_unit_ : 0.0;
      const double j = w.has('J') ? w.get('J') * mm_per_unit_ : 0.0;
      b.center_mm[0] = x0 + i;
      b.center_mm[1] = y0 + j;
      const double r0 = std::hypot(x0 - b.center_mm[0], y0 - b.center_mm[1]);
      const double r1 = std::hypot(x1 - b.center_mm[0], y1 - b.center_mm[1]);
      const std::string ij = fmt::format("I{} J{} r_start {:.6g} mm r_end {:.6g} mm", i, j, r0, r1);
      if (!(r0 > 1e-9)) fail("arc radius must not be 0", ij);
      if (std::abs(r1 - r0) > std::max(kArcRadiusTolerance_mm, kArcRadiusTolerance_rel * r0))
        fail("arc end not on its circle", ij);
    }
  }

  std::string_view name_;
  int line_{0};
  AxisArray<double> pos_mm_;
  double rapid_mm_per_min_;
  std::optional<MotionKind> motion_;
  double mm_per_unit_{1.0};
  bool incremental_{false};
  bool exact_stop_{false};
  bool exact_path_{false};
  double blend_tolerance_mm_{0.0};
  double feed_mm_per_min_{0.0};
  double spindle_speed_rpm_{0.0};
  double spindle_dir_{0.0};
  bool ended_{false};
};

}  // namespace

Program parse_gcode(std::string_view text, std::string_view source_name,
                    const AxisArray<double>& start_mm, double rapid_mm_per_min) {
  for (std::size_t a = 0; a < kNumAxes; ++a)
    if (!std::isfinite(start_mm[a]))
      throw ConfigError(fmt::format("{}: start position {} = {} must be finite", source_name, axis_name(a), start_mm[a]));
  if (!(rapid_mm_per_min > 0.0) || !std::isfinite(rapid_mm_per_min))
    throw ConfigError(fmt::format("{}: rapid rate {} mm/min must be > 0", source_name, rapid_mm_per_min));
  Parser parser(source_name, start_mm, rapid_mm_per_min);
  return parser.run(text);
}

Program load_gcode(const std::string& path, const AxisArray<double>& start_mm,
                   double rapid_mm_per_min) {
  std::error_code ec;
  const auto st = std::filesystem::status(path, ec);
  if (std::filesystem::is_directory(st)) throw IoError(fmt::format("{}: is a directory, not a G-code file", path));
  if (std::filesystem::exists(st) && !std::filesystem::is_regular_file(st))
    throw IoError(fmt::format("{}: not a regular file (a FIFO, device or socket)", path));
  if (std::filesystem::is_regular_file(st) && std::filesystem::file_size(path, ec) > kMaxProgramBytes)
    throw IoError(fmt::format("{}: larger than {} MB, the limit for a G-code file", path, kMaxProgramBytes >> 20));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(fmt::format("{}: cannot open G-code file", path));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw IoError(fmt::format("{}: read error", path));
  return parse_gcode(ss.str(), path, start_mm, rapid_mm_per_min);
}

}  // namespace twin::controller
