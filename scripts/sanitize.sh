#!/usr/bin/env bash
# Builds the whole project and its test suite with clang's AddressSanitizer
# and UndefinedBehaviorSanitizer (float-cast-overflow included; the CMake
# option TWIN_SANITIZE) in build-san/, and runs the test suite there.
#   scripts/sanitize.sh [CTEST-ARGS...]     e.g. scripts/sanitize.sh -R fmu_
# Needs clang++ (Debian: clang-14, libclang-rt-14-dev). Not part of
# scripts/test.sh: on 2 cores the build takes about an hour.
# Reports of code that is not the project's are silenced by file, and only
# those: tests/sanitizers/ubsan.supp and lsan.supp (each entry says why).
# Every other report stops the test that hit it, which then fails. The one
# test left out is tick_allocation_test (it defines malloc, which ASan owns).
set -euo pipefail
cd "$(dirname "$0")/.."
cxx=$(command -v clang++ || true)
if [ -z "$cxx" ]; then
  echo "sanitize.sh: clang++ not found (Debian: clang-14 libclang-rt-14-dev)" >&2
  exit 2
fi
supp="$PWD/tests/sanitizers"
# The same options reach the build (gtest_discover_tests runs each test
# binary once) and every test; a test that runs a command passes them on.
export ASAN_OPTIONS="detect_leaks=1:check_initialization_order=1:strict_init_order=1"
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1:suppressions=$supp/ubsan.supp"
export LSAN_OPTIONS="suppressions=$supp/lsan.supp:print_suppressions=0"
# -O1 with line tables: stacks name file and line; optimised enough that the
# CGAL and SUNDIALS tests run in minutes (unoptimised they take 20-35x longer).
# Configured once: a later run reuses build-san/ (delete it to reconfigure).
[ -f build-san/CMakeCache.txt ] || cmake -S . -B build-san -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_C_COMPILER="${cxx%++}" -DTWIN_SANITIZE=ON \
  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only -DNDEBUG" \
  -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only -DNDEBUG" >/dev/null
start=$SECONDS
cmake --build build-san -j2
echo "sanitize.sh: build $((SECONDS - start)) s"
start=$SECONDS
set +e
ctest --test-dir build-san -j2 --output-on-failure --no-tests=error "$@"
rc=$?
set -e
echo "sanitize.sh: ctest $((SECONDS - start)) s, exit $rc"
exit $rc
