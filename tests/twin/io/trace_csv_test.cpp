// trace.csv reading and writing: a round trip is exact to the printed
// precision; every malformed input is an IoError naming line and column; a
// writer that is not committed leaves nothing at the final name.
#include <filesystem>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_files.hpp"
#include "twin/core/error.hpp"
#include "twin/io/trace_csv.hpp"

namespace twin {
namespace {

using ::testing::HasSubstr;

using test_support::slurp;

std::filesystem::path dir() {
  return test_support::made_dir(std::filesystem::temp_directory_path() / "twin_trace_csv_test");
}

std::filesystem::path write(const std::string& name, const std::string& text) {
  return test_support::write_file(dir() / name, text);
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
    test_support::expect_error<IoError>([&] { io::read_trace_csv(write(name, text)); }, name, what);
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

// The writer formats numbers itself (std::to_chars into a fixed buffer); the
// oracle is the C library's printf "%.10g", which the trace format has always
// used. Exact string equality: both are specified to give the same digits.
TEST(TraceCsv, NumbersAreWrittenAsPrintf10g) {
  const std::vector<double> values{0.1,     1.0 / 3.0, -2.5e-7,  123456789012.0, 1e-300, -1.5e200,
                                   5e-324,  9.999999999e9, 1e10, 0.00012345678912, -0.0, 42.0};
  const auto p = dir() / "fmt.csv";
  {
    io::TraceWriter w(p, {"t_s", "v"});
    for (std::size_t i = 0; i < values.size(); ++i) w.write_row({static_cast<double>(i), values[i]});
    w.commit();
  }
  std::string expected = "t_s,v\n";
  char buf[64];
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double v = values[i] == 0.0 ? 0.0 : values[i];  // the trace never says "-0"
    std::snprintf(buf, sizeof buf, "%.10g,%.10g\n", static_cast<double>(i), v);
    expected += buf;
  }
  EXPECT_EQ(slurp(p), expected);
}

// A trace written as .gz is the plain one compressed: the same bytes once
// gunzipped (oracle: the plain writer's output), read back to the same table.
// 200000 rows cross the writer's buffer and the deflate output buffer many times.
TEST(TraceCsv, GzipTraceIsThePlainTraceCompressed) {
  const auto plain = dir() / "big.csv";
  const auto gz = dir() / "big.csv.gz";
  {
    io::TraceWriter a(plain, {"t_s", "x_mm", "y_mm"});
    io::TraceWriter b(gz, {"t_s", "x_mm", "y_mm"});
    EXPECT_FALSE(a.compressed());
    EXPECT_TRUE(b.compressed());
    for (int k = 0; k < 200000; ++k) {
      const double row[3] = {k * 1e-4, std::sin(k * 1e-3), 1e-3 * (k % 977)};
      a.write_row(row, 3);
      b.write_row(row, 3);
    }
    EXPECT_EQ(b.num_rows(), 200000u);
    a.commit();
    b.commit();
  }
  EXPECT_LT(std::filesystem::file_size(gz), std::filesystem::file_size(plain) / 2);
  const auto back = dir() / "big_back.csv";
  io::gunzip_file(gz, back);
  EXPECT_EQ(slurp(back), slurp(plain));
  const io::TraceTable tp = io::read_trace_csv(plain);
  const io::TraceTable tg = io::read_trace_csv(gz);
  ASSERT_EQ(tg.num_rows(), 200000u);
  EXPECT_EQ(tg.columns, tp.columns);
}

TEST(TraceCsv, NonFiniteValueIsAnErrorNamingTheColumn) {
  const auto p = dir() / "nan_out.csv.gz";
  io::TraceWriter w(p, {"t_s", "x_mm"});
  const double row[2] = {0.0, std::nan("")};
  try {
    w.write_row(row, 2);
    ADD_FAILURE() << "no error";
  } catch (const ModelError& e) {
    EXPECT_THAT(e.what(), HasSubstr("x_mm"));
  }
  const double wrong[1] = {0.0};
  EXPECT_THROW(w.write_row(wrong, 1), IoError);
}

TEST(TraceCsv, TraceFormatNames) {
  EXPECT_EQ(io::parse_trace_format("csv"), io::TraceFormat::kCsv);
  EXPECT_EQ(io::parse_trace_format("csv.gz"), io::TraceFormat::kCsvGz);
  EXPECT_STREQ(io::trace_file_name(io::TraceFormat::kCsvGz), "trace.csv.gz");
  EXPECT_THROW(io::parse_trace_format("parquet"), ConfigError);
}

}  // namespace
}  // namespace twin
