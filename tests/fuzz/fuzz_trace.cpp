// libFuzzer harness: the trace.csv reader (twin/io/trace_csv), plain and,
// when the input starts with the gzip magic, compressed.
#include <cstdint>

#include "fuzz_util.hpp"
#include "twin/io/trace_csv.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const bool gz = size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
  const auto path = twin::fuzz::put(gz ? "trace.csv.gz" : "trace.csv", data, size);
  twin::fuzz::expect_contract([&] { static_cast<void>(twin::io::read_trace_csv(path)); });
  return 0;
}
