#!/usr/bin/env bash
# `make fuzz` (issue 24): builds the libFuzzer targets (fuzz/) with clang, AddressSanitizer and
# UndefinedBehaviorSanitizer in the sanitizer build tree (scripts/sanitize_tree.sh, shared
# with check-asan.sh), writes their seed corpora, runs
# each target for FUZZ_SECONDS and fails on any crash, leak, sanitizer report or timeout
# (the input that did it is kept under $SANITIZE_BUILD/artifacts). The executions each target
# reached go to $FUZZ_OUT/fuzz.json.
#   FUZZ_SECONDS  seconds a target (default 60)
#   FUZZ_RUNS     stop a target after this many inputs instead, if sooner (default: no limit;
#                 the long run of bench/results/fuzz.json used 10000000)
#   FUZZ_TARGETS  which (default: frame gltf exr script)
#   SANITIZE_BUILD  the build tree (default build-sanitize, shared with check-asan.sh); its
#                   corpus/ keeps what was found
#   SANITIZE_FLAGS  compiler flags of a new tree (scripts/sanitize_tree.sh). For a long run of
#                   the EXR target: without ASan (OpenEXR allocates what an attribute's declared
#                   size says and ASan poisons each allocation, 230 inputs/s), e.g.
#                   SANITIZE_BUILD=build-fuzz-ubsan SANITIZE_FLAGS="-O1 -g -fsanitize=fuzzer-no-link,undefined -fno-sanitize-recover=all"
#                   (clang 14 cannot link LeakSanitizer beside UBSan alone: leaks go unchecked there)
#   FUZZ_OUT      where fuzz.json goes (default: the build tree; bench/results to record)
#   FUZZ_SEED     libFuzzer's random seed (default: a new one each run; make check sets 1,
#                 so that a CI run does the same work every time)
#   JOBS          build jobs, and how many targets fuzz at once (default: the cores)
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${FUZZ_SECONDS:-60}
runs=${FUZZ_RUNS:--1}
targets=${FUZZ_TARGETS:-frame gltf exr script}
# shellcheck source=scripts/sanitize_tree.sh
source scripts/sanitize_tree.sh
build=$sanitize_build
out=${FUZZ_OUT:-$build}
jobs=${JOBS:-$(nproc)}
seed=${FUZZ_SEED:-0}
names=fuzz_seeds
for t in $targets; do names="$names fuzz_$t"; done
# shellcheck disable=SC2086
cmake --build "$build" -j "$jobs" --target $names
"$build/fuzz/fuzz_seeds" . "$build/corpus"

mkdir -p "$build/artifacts" "$out"
# One target: its log, then one line of JSON in $build/fuzz_$t.result; returns non-zero on a
# report.
fuzz_target() {
    local t=$1 log="$build/fuzz_$1.log" crashes=0
    # A script is parsed line by line with the app cleared between lines, so a long input
    # only repeats what short ones do: without a bound libFuzzer grows inputs to kilobytes of
    # lines (850 inputs/s on one core under the sanitizers, against 3,500 at 256 bytes, the
    # same coverage).
    local options=()
    [ "$t" = script ] && options=(-max_len=256)
    if ! "$build/fuzz/fuzz_$t" "${options[@]}" -max_total_time="$seconds" -runs="$runs" -timeout=10 -rss_limit_mb=2048 -seed="$seed" \
        -print_final_stats=1 -artifact_prefix="$build/artifacts/$t-" "$build/corpus/$t" \
        >"$log" 2>&1; then
        crashes=1
    fi
    local executed took corpus
    executed=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    took=$(sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' "$log" | tail -1)
    corpus=$(find "$build/corpus/$t" -type f | wc -l)
    echo "\"$t\": {\"executions\": ${executed:-0}, \"seconds\": ${took:-$seconds}, \"corpus\": $corpus, \"failed\": $crashes}" \
        >"$build/fuzz_$t.result"
    return $crashes
}

# The targets run JOBS at a time (each is one process on one core).
for t in $targets; do
    while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n || true; done
    echo "fuzz_$t: $seconds s"
    rm -f "$build/fuzz_$t.result"
    fuzz_target "$t" &
done
wait || true
json="{\"device\": \"$(uname -m), $(nproc) cores (CPU; the fuzz targets use no GPU)\", \"date\": \"$(date -u +%Y-%m-%d)\", \"seconds_per_target\": $seconds, \"targets\": {"
first=1
status=0
for t in $targets; do
    result=$(cat "$build/fuzz_$t.result" 2>/dev/null || echo "\"$t\": {\"failed\": 1}")
    if [[ "$result" == *'"failed": 1'* ]]; then
        status=1
        echo "fuzz_$t FAILED: the last lines of $build/fuzz_$t.log:"
        tail -40 "$build/fuzz_$t.log"
    fi
    echo "  fuzz_$t: $result"
    [ $first -eq 1 ] || json="$json, "
    first=0
    json="$json$result"
done
echo "$json}}" >"$out/fuzz.json"
echo "wrote $out/fuzz.json"
exit $status
