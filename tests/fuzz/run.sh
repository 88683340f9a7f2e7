#!/usr/bin/env bash
# Builds the libFuzzer harnesses (clang 14, -fsanitize=fuzzer,address; TB_BUILD_FUZZ) into
# build-fuzz/ and runs every tests/fuzz/fuzz_NAME.cpp that was built for FUZZ_SECONDS seconds
# each (default 30), starting from its seed corpus tests/fuzz/corpus/fuzz_NAME/ (copied, so the
# checked-in seeds stay as they are). Exits 1 at the first harness that finds a crash, leak or
# sanitizer report; the input that shows it is left in build-fuzz/fuzz_NAME-crash-*.
#   tests/fuzz/run.sh                  all harnesses, 30 s each
#   FUZZ_SECONDS=300 tests/fuzz/run.sh fuzz_routes
#   FUZZ_SEED=1 tests/fuzz/run.sh      the same inputs every run (CI), else a random seed
set -euo pipefail
cd "$(dirname "$0")/../.."
BUILD=${FUZZ_BUILD:-build-fuzz}
SECONDS_EACH=${FUZZ_SECONDS:-30}
SEED=${FUZZ_SEED:-0} # libFuzzer: 0 picks a random seed
JOBS=${JOBS:-$(nproc)}

log() { printf '%s fuzz: %s\n' "$(date -u +%FT%TZ)" "$*" >&2; }

cmake -S . -B "$BUILD" -DCMAKE_CXX_COMPILER=clang++-14 -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DTB_BUILD_TESTS=OFF -DTB_BUILD_FUZZ=ON >/dev/null
cmake --build "$BUILD" -j "$JOBS" --target fuzz >/dev/null

names=("$@")
if [ ${#names[@]} -eq 0 ]; then
    for src in tests/fuzz/fuzz_*.cpp; do
        names+=("$(basename "$src" .cpp)")
    done
fi
ran=0
for name in "${names[@]}"; do
    bin="$BUILD/$name"
    if [ ! -x "$bin" ]; then
        log "$name: not built; skipped"
        continue
    fi
    corpus=$(mktemp -d)
    trap 'rm -rf "$corpus"' EXIT
    if [ -d "tests/fuzz/corpus/$name" ]; then
        cp -r "tests/fuzz/corpus/$name/." "$corpus/"
    fi
    log "$name: ${SECONDS_EACH} s from $(find "$corpus" -type f | wc -l) seed(s)"
    if ! "$bin" -seed="$SEED" -max_total_time="$SECONDS_EACH" -timeout=20 -rss_limit_mb=4096 \
        -print_final_stats=1 -artifact_prefix="$BUILD/$name-" "$corpus" \
        >"$BUILD/$name.log" 2>&1; then
        tail -n 60 "$BUILD/$name.log" >&2
        log "$name: FAILED; the input is in $BUILD/$name-*; add it as a regression test"
        exit 1
    fi
    log "$name: ok, $(grep -o 'stat::number_of_executed_units: *[0-9]*' "$BUILD/$name.log" |
        grep -o '[0-9]*$') runs, corpus $(find "$corpus" -type f | wc -l) inputs"
    rm -rf "$corpus"
    trap - EXIT
    ran=$((ran + 1))
done
echo "fuzz: $ran passed, 0 failed"
