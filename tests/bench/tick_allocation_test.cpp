// No allocation per tick. This executable replaces the global operator new
// (and so every allocation of the standard library and of the twin's
// libraries linked into it) with one that counts calls. After a warm-up that
// covers each kind of tick once (start from rest, sliding, stops, reversals,
// and cutting in the coupled case), N further ticks of the co-simulation on
// the default scenario must not allocate at all.
//
// The C libraries (SUNDIALS) allocate with malloc, not new: malloc, calloc
// and realloc are interposed too (glibc lets the executable define them and
// forward to __libc_malloc and friends), and their calls counted separately.
//
// Oracle: the counts themselves (zero is the specification). They cannot pass
// vacuously: CountsTheAllocationsOfAVector checks both counters see
// allocations made on purpose (a vector, a malloc, a SUNDIALS set-up).
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <new>
#include <vector>

#include "feeddrive/drive_bank.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/sim/scenario.hpp"
#include "twin/sim/cosimulation.hpp"

namespace {
std::atomic<long> g_allocations{0};
std::atomic<long> g_mallocs{0};
}  // namespace

extern "C" {
void* __libc_malloc(std::size_t n);
void* __libc_calloc(std::size_t n, std::size_t size);
void* __libc_realloc(void* p, std::size_t n);
void __libc_free(void* p);
void* malloc(std::size_t n) noexcept {
  g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) noexcept {
  g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_realloc(p, n);
}
}

void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = __libc_malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = __libc_malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n == 0 ? 1 : n);
}
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { __libc_free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { __libc_free(p); }

namespace twin {
namespace {

TEST(TickAllocation, CountsTheAllocationsOfAVector) {
  const long before = g_allocations.load();
  auto v = std::make_unique<std::vector<double>>(100, 1.0);
  EXPECT_GE(g_allocations.load() - before, 2);
  EXPECT_EQ(v->size(), 100u);
  const long before_c = g_mallocs.load();
  void* c = std::malloc(16);
  EXPECT_EQ(g_mallocs.load() - before_c, 1);
  std::free(c);
  // SUNDIALS (C, linked statically) allocates its vectors and memory with malloc.
  const long before_s = g_mallocs.load();
  feeddrive::DriveBank bank({feeddrive::DriveParams{1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, {}}}, 1e-4);
  EXPECT_GT(g_mallocs.load() - before_s, 2);
}

struct Counts {
  long news{0};
  long mallocs{0};
};

// Runs the default scenario (air cut or coupled): `warmup` ticks, then counts
// the allocations of the next `n` ticks.
Counts allocations_in_ticks(bool coupled, std::int64_t warmup, std::int64_t n) {
  const io::Scenario sc = io::load_scenario(io::default_scenario_path());
  const auto ref = sim::plan_program(sc, sc.machine).reference;
  EXPECT_GE(ref->num_ticks(), warmup + n);
  sim::CoSimulation cs = sim::build_cosimulation(sc, {.reference = ref, .air_cut = !coupled});
  double sink = 0.0;
  for (std::int64_t k = 0; k < warmup; ++k) sink += cs.step().contour_error_mm;
  const long before = g_allocations.load();
  const long before_c = g_mallocs.load();
  for (std::int64_t k = 0; k < n; ++k) sink += cs.step().contour_error_mm;
  const Counts c{g_allocations.load() - before, g_mallocs.load() - before_c};
  EXPECT_TRUE(std::isfinite(sink));
  return c;
}

// The default program starts with a rapid, then cuts from about 1 s on; 2 s
// of warm-up reach the cut, the 5 s counted hold the corner, the reversal-free
// feed, the stops at block ends and the retract.
TEST(TickAllocation, AirCutTicksAllocateNothing) {
  const Counts c = allocations_in_ticks(false, 20000, 50000);
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

TEST(TickAllocation, CoupledTicksAllocateNothing) {
  const Counts c = allocations_in_ticks(true, 20000, 50000);
  EXPECT_EQ(c.news, 0);
  EXPECT_EQ(c.mallocs, 0);
}

}  // namespace
}  // namespace twin
