// trace.csv reading and writing: a round trip is exact to the printed
// precision; every malformed input is an IoError naming line and column; a
// writer that is not committed leaves nothing at the final name.
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "twin/core/error.hpp"
#include "twin/io/trace_csv.hpp"

namespace twin {
namespace {

using ::testing::HasSubstr;

std::filesystem::path dir() {
  const auto d = std::filesystem::temp_directory_path() / "twin_trace_csv_test";
  std::filesystem::create_directories(d);
  return d;
}

std::filesystem::path write(const std::string& name, const std::string& text) {
  const auto p = dir() / name;
  std::ofstream(p) << text;
  return p;
}

TEST(TraceCsv, RoundTrip) {
  const auto p = dir() / "rt.csv";
  {
    io::TraceWriter w(p, {"t_s", "x_ref_mm", "x_mm"});
    for (int k = 0; k < 1000; ++k) w.write_row({k * 1e-4, 0.1234567891 * k, -0.001 * k});
    w.commit();
  }
  const io::TraceTable t = io::read_trace_csv(p);
  ASSERT_EQ(t.num_rows(), 1000u);
  for (int k = 0; k < 1000; ++k) {
    // Ten significant digits are printed: relative error below 1e-9.
    EXPECT_NEAR(t.at("x_ref_mm")[k], 0.1234567891 * k, 1e-9 * std::max(1.0, 0.12 * k));
    EXPECT_NEAR(t.at("t_s")[k], k * 1e-4, 1e-13);
  }
  EXPECT_EQ(t.find("y_mm"), nullptr);
  EXPECT_THROW(t.at("y_mm"), IoError);
}

TEST(TraceCsv, UncommittedWriterLeavesNoFile) {
  const auto p = dir() / "half.csv";
  std::filesystem::remove(p);
  {
    io::TraceWriter w(p, {"t_s"});
    w.write_row({0.0});
  }
  EXPECT_FALSE(std::filesystem::exists(p));
  for (const auto& e : std::filesystem::directory_iterator(dir()))
    EXPECT_EQ(e.path().string().find("half.csv.tmp"), std::string::npos);
}

TEST(TraceCsv, MalformedInputsNameTheLine) {
  auto expect_error = [](const std::string& name, const std::string& text, const std::string& what) {
    try {
      io::read_trace_csv(write(name, text));
      ADD_FAILURE() << name << ": no error";
    } catch (const IoError& e) {
      EXPECT_THAT(e.what(), HasSubstr(what)) << name;
    }
  };
  expect_error("nan.csv", "t_s,x_mm\n0,1\n0.1,nan\n", ":3: column x_mm");
  expect_error("short.csv", "t_s,x_mm\n0,1\n0.1\n", ":3:");
  expect_error("long.csv", "t_s,x_mm\n0,1,2\n", ":2:");
  expect_error("text.csv", "t_s,x_mm\n0,abc\n", "'abc' is not a number");
  expect_error("empty.csv", "", "empty");
  expect_error("notime.csv", "x_mm\n1\n", "missing column t_s");
  expect_error("back.csv", "t_s,x_mm\n0,1\n0.2,1\n0.1,1\n", "not increasing");
  expect_error("dup.csv", "t_s,t_s\n0,1\n", "appears twice");
}

}  // namespace
}  // namespace twin
