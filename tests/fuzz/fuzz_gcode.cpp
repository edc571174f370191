// libFuzzer harness: the G-code reader, the travel check and the planner.
#include <cstdint>
#include <string_view>

#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace twin::controller;
  twin::fuzz::expect_contract([&] {
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const Program p = parse_gcode(text, "fuzz.nc", {0.0, 0.0, 0.0}, 10160.0);
    // The FADAL 2216 travel and limits (scenarios/machines/fadal2216.yaml).
    check_travel(p, {0.0, 0.0, -508.0}, {559.0, 406.0, 0.0});
    MotionLimits lim;
    lim.v_max_mm_per_s = {169.3, 169.3, 169.3};
    lim.a_max_mm_per_s2 = {2000.0, 2000.0, 2000.0};
    lim.j_max_mm_per_s3 = {50000.0, 50000.0, 50000.0};
    const Trajectory t = plan_trajectory(p, lim, 1e-4);
    const std::int64_t n = t.num_ticks();
    for (std::int64_t k : {std::int64_t{0}, n / 2, n}) static_cast<void>(t.sample(k));
  });
  return 0;
}
