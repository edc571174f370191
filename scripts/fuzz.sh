#!/usr/bin/env bash
# Builds the fuzz harnesses of tests/fuzz with clang's libFuzzer, the
# project's own code instrumented for coverage and checked by ASan and UBSan
# (float-cast-overflow included), in build-fuzz/, and runs each harness for
# SECONDS (default 600) from its seed corpus, one at a time.
#   scripts/fuzz.sh [SECONDS] [HARNESS...]     harnesses: gcode machine scenario process trace
# Needs clang++ and libFuzzer (Debian: clang-14, libclang-rt-14-dev).
# New corpus entries go to build-fuzz/corpus/<h>; findings (crash-*, leak-*,
# timeout-*) to build-fuzz/findings/<h>. Prints one summary line per harness.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-600}
shift || true
harnesses=("$@")
((${#harnesses[@]})) || harnesses=(gcode machine scenario process trace)
cxx=$(command -v clang++ || true)
if [ -z "$cxx" ]; then
  echo "fuzz.sh: clang++ not found (Debian: clang-14 libclang-rt-14-dev)" >&2
  exit 2
fi
san="-fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=undefined,float-cast-overflow"
# Configured once: a later run reuses build-fuzz/ as it is (delete it to reconfigure).
[ -f build-fuzz/CMakeCache.txt ] || cmake -S . -B build-fuzz -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_C_COMPILER="${cxx%++}" \
  -DCMAKE_CXX_FLAGS="-fsanitize=fuzzer-no-link $san" \
  -DCMAKE_EXE_LINKER_FLAGS="$san" -DCMAKE_SHARED_LINKER_FLAGS="$san" >/dev/null
targets=()
for h in "${harnesses[@]}"; do targets+=("fuzz_$h"); done
cmake --build build-fuzz -j2 --target "${targets[@]}"
for h in "${harnesses[@]}"; do
  mkdir -p "build-fuzz/corpus/$h" "build-fuzz/findings/$h"
  log="build-fuzz/findings/$h/fuzz.log"
  # Leaks are not findings here: a reader that throws leaks nothing, and
  # yaml-cpp keeps node memory pools alive by design.
  start=$SECONDS
  set +e
  ASAN_OPTIONS=detect_leaks=0 UBSAN_OPTIONS=print_stacktrace=1 \
    "build-fuzz/tests/fuzz_$h" -max_total_time="$seconds" -max_len=4096 -timeout=20 -rss_limit_mb=2048 \
    -print_final_stats=1 -artifact_prefix="build-fuzz/findings/$h/" \
    "build-fuzz/corpus/$h" "tests/fuzz/corpus/$h" >"$log" 2>&1
  rc=$?
  set -e
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || echo "?")
  corpus=$(find "build-fuzz/corpus/$h" -type f | wc -l)
  findings=$(find "build-fuzz/findings/$h" -type f ! -name fuzz.log | wc -l)
  echo "fuzz_$h: $((SECONDS - start)) s, exit $rc, $runs runs, coverage $cov edges, corpus +$corpus, findings $findings"
done
