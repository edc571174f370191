// Tests of the G-code interpreter. Oracle: the program text itself, read by
// hand (coordinates, modal states, arc centres by plane geometry), and the
// error contract "file:line: what (word)". Coordinates are compared to 1e-12
// mm: the parser only adds and scales decimal numbers.
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "controller/gcode.hpp"
#include "twin/core/error.hpp"

namespace twin::controller {
namespace {

constexpr double kRapid_mm_per_min = 10160.0;
constexpr double kTol_mm = 1e-12;

Program parse(const std::string& text, AxisArray<double> start = {0.0, 0.0, 0.0}) {
  return parse_gcode(text, "prog.nc", start, kRapid_mm_per_min);
}

void expect_xyz(const AxisArray<double>& p, double x, double y, double z) {
  EXPECT_NEAR(p[0], x, kTol_mm);
  EXPECT_NEAR(p[1], y, kTol_mm);
  EXPECT_NEAR(p[2], z, kTol_mm);
}

/// The parser must throw ConfigError whose message names prog.nc:<line>.
void expect_error_at(const std::string& text, int line, const std::string& fragment) {
  try {
    parse(text);
    ADD_FAILURE() << "no error for: " << text;
  } catch (const ConfigError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("prog.nc:" + std::to_string(line) + ":"), std::string::npos) << msg;
    EXPECT_NE(msg.find(fragment), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "one-line message: " << msg;
  }
}

// Every supported word on the lines of a small program, modal G1 and F.
TEST(GcodeParser, ReadsEverySupportedWordAndModalMotion) {
  const Program p = parse(
      "%\n"
      "(pocket, comment) ; another comment\n"
      "N10 G17 G21 G90 G64 P0.02 T1\n"
      "n20 s12000 m3\n"
      "G0 X10 Y5 Z2\n"
      "G1 Z-1 F600\n"
      "X20 (modal G1 and F)\n"
      "G61 Y15\n"
      "G61.1 G4 P0.5\n"
      "M4 S500\n"
      "g2 x30 y5 i0 j-10\n"
      "M5\n"
      "M30\n"
      "G1 X99 (after M30: not read)\n"
      "%\n");
  ASSERT_EQ(p.blocks.size(), 6u);
  const Block& rapid = p.blocks[0];
  EXPECT_EQ(rapid.kind, MotionKind::kRapid);
  EXPECT_EQ(rapid.line, 5);
  expect_xyz(rapid.end_mm, 10, 5, 2);
  EXPECT_DOUBLE_EQ(rapid.feed_mm_per_min, kRapid_mm_per_min);
  EXPECT_DOUBLE_EQ(rapid.spindle_rpm, 12000.0);
  EXPECT_DOUBLE_EQ(rapid.blend_tolerance_mm, 0.02);
  EXPECT_FALSE(rapid.exact_stop);

  const Block& plunge = p.blocks[1];
  EXPECT_EQ(plunge.kind, MotionKind::kLinear);
  expect_xyz(plunge.start_mm, 10, 5, 2);
  expect_xyz(plunge.end_mm, 10, 5, -1);
  EXPECT_DOUBLE_EQ(plunge.feed_mm_per_min, 600.0);

  const Block& modal = p.blocks[2];
  EXPECT_EQ(modal.kind, MotionKind::kLinear);
  EXPECT_EQ(modal.line, 7);
  expect_xyz(modal.end_mm, 20, 5, -1);
  EXPECT_DOUBLE_EQ(modal.feed_mm_per_min, 600.0);

  // G61 is LinuxCNC's exact path, G61.1 its exact stop (Fanuc's G61).
  EXPECT_TRUE(p.blocks[3].exact_path);
  EXPECT_FALSE(p.blocks[3].exact_stop);
  EXPECT_TRUE(p.blocks[4].exact_stop);
  EXPECT_FALSE(p.blocks[4].exact_path);
  expect_xyz(p.blocks[3].end_mm, 20, 15, -1);

  EXPECT_EQ(p.blocks[4].kind, MotionKind::kDwell);
  EXPECT_DOUBLE_EQ(p.blocks[4].dwell_s, 0.5);
  expect_xyz(p.blocks[4].end_mm, 20, 15, -1);

  const Block& arc = p.blocks[5];
  EXPECT_EQ(arc.kind, MotionKind::kArcCw);
  EXPECT_DOUBLE_EQ(arc.spindle_rpm, -500.0);  // M4: negative
  expect_xyz(arc.center_mm, 20, 5, -1);
  expect_xyz(arc.end_mm, 30, 5, -1);
  EXPECT_DOUBLE_EQ(p.spindle_rpm_at_end, 0.0);
}

// G91: each coordinate adds to the previous end; G90 returns to absolute.
TEST(GcodeParser, IncrementalMode) {
  const Program p = parse("G91 G1 X1 Y2 F100\nX1\nY-4 Z0.5\nG90 X0 Y0\n", {5.0, 5.0, 5.0});
  ASSERT_EQ(p.blocks.size(), 4u);
  expect_xyz(p.blocks[0].end_mm, 6, 7, 5);
  expect_xyz(p.blocks[1].end_mm, 7, 7, 5);
  expect_xyz(p.blocks[2].end_mm, 7, 3, 5.5);
  expect_xyz(p.blocks[3].end_mm, 0, 0, 5.5);
}

// G20: X Y Z I J, F and G64 P are inches (25.4 mm); G4 P stays in seconds.
TEST(GcodeParser, InchUnits) {
  const Program p = parse("G20 G64 P0.001\nG1 X1 Y-0.5 F10\nG3 X2 Y0.5 I0 J1\nG4 P2\nG21 G1 X0\n");
  ASSERT_EQ(p.blocks.size(), 4u);
  expect_xyz(p.blocks[0].end_mm, 25.4, -12.7, 0);
  EXPECT_NEAR(p.blocks[0].feed_mm_per_min, 254.0, 1e-12);
  EXPECT_NEAR(p.blocks[0].blend_tolerance_mm, 0.0254, 1e-15);
  expect_xyz(p.blocks[1].center_mm, 25.4, 12.7, 0);
  EXPECT_DOUBLE_EQ(p.blocks[2].dwell_s, 2.0);
  expect_xyz(p.blocks[3].end_mm, 0, 12.7, 0);
}

// I J K arcs: centre = start + (I, J); K is accepted and ignored in G17.
// Helical Z is carried to the end point.
TEST(GcodeParser, IjkArcsAndHelix) {
  const Program p = parse("G1 X10 F100\nG3 X0 Y10 I-10 J0 K5 Z-2\nG2 X10 Y0 I0 J-10\n");
  ASSERT_EQ(p.blocks.size(), 3u);
  EXPECT_EQ(p.blocks[1].kind, MotionKind::kArcCcw);
  expect_xyz(p.blocks[1].center_mm, 0, 0, 0);
  expect_xyz(p.blocks[1].end_mm, 0, 10, -2);
  EXPECT_EQ(p.blocks[2].kind, MotionKind::kArcCw);
  expect_xyz(p.blocks[2].center_mm, 0, 0, -2);
}

// R arcs, both signs: quarter circle from (10,0) to (0,10) with |R| = 10.
// Oracle: the two circles of radius 10 through both points have centres
// (0,0) and (10,10). G3 R+10 (short way, CCW) turns about (0,0); G3 R-10
// (long way) about (10,10); G2 R+10 about (10,10); G2 R-10 about (0,0).
TEST(GcodeParser, RArcsBothSigns) {
  struct Case {
    const char* code;
    double cx, cy;
  };
  for (const Case c : {Case{"G3 X0 Y10 R10", 0, 0}, Case{"G3 X0 Y10 R-10", 10, 10},
                       Case{"G2 X0 Y10 R10", 10, 10}, Case{"G2 X0 Y10 R-10", 0, 0}}) {
    const Program p = parse(std::string("G1 X10 F100\n") + c.code + "\n");
    ASSERT_EQ(p.blocks.size(), 2u) << c.code;
    EXPECT_NEAR(p.blocks[1].center_mm[0], c.cx, 1e-9) << c.code;
    EXPECT_NEAR(p.blocks[1].center_mm[1], c.cy, 1e-9) << c.code;
  }
}

// Blank lines, CRLF line ends, spaces inside words and lower case.
TEST(GcodeParser, WhitespaceCaseAndLineEnds) {
  const Program p = parse("\r\n  \r\ng1 x 1.5 y-.5 f 100\r\n\n;only comment\n(only comment)\nG1X+2.\n");
  ASSERT_EQ(p.blocks.size(), 2u);
  EXPECT_EQ(p.blocks[0].line, 3);
  expect_xyz(p.blocks[0].end_mm, 1.5, -0.5, 0);
  EXPECT_EQ(p.blocks[1].line, 7);
  expect_xyz(p.blocks[1].end_mm, 2, -0.5, 0);
}

// Words accepted without effect (README: T, M8 M9, G40 G49 G54 G80 G94) and
// M2 ending the program: only the one motion before M2 is read.
TEST(GcodeParser, AcceptedWithoutEffectAndM2) {
  const Program p = parse("G40 G49 G54 G80 G94 M8 S800 M3\nG1 X1 F100 T2\nM9\nM2\nG1 X5\n");
  ASSERT_EQ(p.blocks.size(), 1u);
  expect_xyz(p.blocks[0].end_mm, 1, 0, 0);
  EXPECT_DOUBLE_EQ(p.blocks[0].spindle_rpm, 800.0);
  EXPECT_DOUBLE_EQ(p.spindle_rpm_at_end, 0.0);
}

// Errors: each names prog.nc:<line> and what is wrong.
TEST(GcodeParser, ErrorsNameFileAndLine) {
  expect_error_at("G1 X1 F100\nG41 X2\n", 2, "unknown G code");
  expect_error_at("G1 X1 F100\nM6\n", 2, "unknown M code");
  expect_error_at("G1 X1..2 F100\n", 1, "malformed number");
  expect_error_at("G1 X F100\n", 1, "malformed number");
  expect_error_at("G1 X1-2 F100\n", 1, "malformed number");
  expect_error_at("G0 X1\nG1 X2\n", 2, "no F");
  expect_error_at("G1 X10 F100\nG2 X0 Y10 I-10 J0.5\n", 2, "not on its circle");
  expect_error_at("G1 X10 F100\n\nG2 X-30 Y0 R10\n", 3, "R arc impossible");
  expect_error_at("G1 X1 F100\nG3 X1 Y0 R5\n", 2, "R arc");
  expect_error_at("X1\n", 1, "without a motion mode");
  expect_error_at("G1 X1 X2 F100\n", 1, "twice");
  expect_error_at("G1 X1 F100 (open comment\n", 1, "comment not closed");
  expect_error_at("G1 X1 F100 Q3\n", 1, "unsupported word");
  expect_error_at("G18\n", 1, "G17");
  expect_error_at("G1 X1 F100 P2\n", 1, "P without G4 or G64");
  expect_error_at("G1 X1 F-5\n", 1, "feed must be > 0");
  expect_error_at("G0 G1 X1 F100\n", 1, "two motion codes");
  expect_error_at("G1 X1 R3 F100\n", 1, "arc words on a straight move");
  expect_error_at("G4\n", 1, "G4 needs P");
  expect_error_at("@G1 X1 F100\n", 1, "expected a letter");
  expect_error_at("G1 X1 F100 @\n", 1, "malformed number");
}

TEST(GcodeParser, LoadMissingFileIsIoError) {
  EXPECT_THROW(load_gcode("/nonexistent/dir/x.nc", {0, 0, 0}, kRapid_mm_per_min), IoError);
}

// Hostile words (issue 19). Oracle: the word as written; before these
// checks G100000000000000000000 ran as G0 (lround overflow) and M6e16 was
// undefined behaviour.
TEST(GcodeParser, IntegerWordsRangeChecked) {
  expect_error_at("G21\nG100000000000000000000 X2\n", 2, "unknown G code");
  expect_error_at("G1 X1 F100\nM60000000000000000\n", 2, "unknown M code");
  expect_error_at("G1 X1 F100\nM-60000000000000000\n", 2, "unknown M code");
  expect_error_at("G1 X1 F100\nG-1\n", 2, "unknown G code");
  expect_error_at("N1.5 G1 X1 F100\n", 1, "N must be a whole number");
  expect_error_at("N10000000000 G1 X1 F100\n", 1, "N must be a whole number");
  expect_error_at("T-1\nG1 X1 F100\n", 1, "T must be a whole number");
  expect_error_at("T2.5\nG1 X1 F100\n", 1, "T must be a whole number");
  expect_error_at("S100000000000000000000 M3\nG1 X1 F100\n", 1, "spindle speed beyond 200000 rpm");
  expect_error_at("S200001 M3\nG1 X1 F100\n", 1, "spindle speed beyond 200000 rpm");
  // The edges themselves are accepted.
  const Program p = parse("N999999999 T999999 S200000 M3\nG1 X1 F100\n");
  EXPECT_EQ(p.blocks.front().spindle_rpm, 200000.0);
}

TEST(GcodeParser, ProgramWithoutMotionRefused) {
  expect_error_at("", 1, "holds no move");
  expect_error_at("%\n%\n", 2, "holds no move");
  expect_error_at("%\nG21 G90 (settings only)\nM3 S1000\nM30\n%\n", 4, "holds no move");
  // A dwell alone is a program.
  EXPECT_EQ(parse("G4 P0.5\n").blocks.size(), 1u);
}

TEST(GcodeParser, ErrorQuotesAShortEscapedExcerpt) {
  // A 1 MB comment that is never closed, with control bytes and a NUL.
  std::string text = "G1 X1 F100 (";
  text += std::string("\x01\x1b[31m", 6);
  text += std::string(1 << 20, 'A');
  text.push_back('\0');
  text += "tail\n";
  try {
    parse(text);
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    const std::string msg = e.what();
    EXPECT_LT(msg.size(), 200u) << msg.size();
    EXPECT_NE(msg.find("prog.nc:1: comment not closed (G1 X1 F100 (\\x01\\x1b[31mAAAA"), std::string::npos) << msg;
    EXPECT_NE(msg.find("...)"), std::string::npos) << msg;
    for (char c : msg) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << static_cast<int>(static_cast<unsigned char>(c));
  }
}

TEST(GcodeParser, LoadRefusesDirectoriesAndSpecialFiles) {
  try {
    load_gcode("/tmp", {0, 0, 0}, kRapid_mm_per_min);
    ADD_FAILURE() << "no error";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("is a directory"), std::string::npos) << e.what();
  }
  try {
    load_gcode("/dev/zero", {0, 0, 0}, kRapid_mm_per_min);
    ADD_FAILURE() << "no error";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace twin::controller
