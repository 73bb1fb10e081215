# Sourced by fuzz.sh and check-asan.sh: the build tree both use, compiled with clang,
# AddressSanitizer, UndefinedBehaviorSanitizer (every report fatal) and libFuzzer's coverage
# instrumentation (harmless to programs that are not fuzz targets). No benchmarks: no test
# runs them, and building them sanitized cost CI a minute.
sanitize_build=${SANITIZE_BUILD:-build-sanitize}
# SANITIZE_FLAGS replaces the flags for a tree of its own (a fuzz run without ASan, say:
# scripts/fuzz.sh says when that is worth it); a tree keeps the flags it was configured with.
# Line tables only: reports still name file and line, and the files compile 15% faster
# (implicit_solver.cpp: 19.5 -> 16.5 s) into objects half the size. -O3 -DNDEBUG, as the
# Release tree ships: the build type Sanitize adds no flags of its own (an empty type became
# Release, which appended these same two after an -O1 here). Tried: -O2 with the libraries'
# asserts on (no NDEBUG; GLM asserts every vector index): the quick suite took 584 s against
# about 370 before (one run; which of the two cost it was not measured). Unity batches, as
# the Makefile's tree: about 30% less compile time. UBSan without its alignment and
# pointer-overflow checks, for CI's time (a server file batch 48.6 -> 36.8 s with null too,
# 44.7 s without pointer-overflow alone): the targets are x86-64, where a misaligned load is
# not a fault, the readers of untrusted bytes copy them out (memcpy, FlatBuffers' verifier),
# and ASan still catches a pointer that arithmetic took out of its allocation when it is read.
# The tests' own files are built without the sanitizers (tests/CMakeLists.txt says why).
sanitize_flags=${SANITIZE_FLAGS:-"-O3 -DNDEBUG -gline-tables-only -fno-omit-frame-pointer -fsanitize=fuzzer-no-link,address,undefined -fno-sanitize=alignment,pointer-overflow -fno-sanitize-recover=all"}
if [ ! -f "$sanitize_build/CMakeCache.txt" ]; then
    cmake -S . -B "$sanitize_build" -DCMAKE_BUILD_TYPE=Sanitize -DCMAKE_UNITY_BUILD=ON -DCMAKE_CXX_COMPILER=clang++ \
        -DCMAKE_CXX_FLAGS="$sanitize_flags" -DPENUMBRA_FUZZ=ON -DPENUMBRA_BENCH=OFF >/dev/null
fi
# Leaks in the system's own libraries (the Vulkan loader and Mesa's drivers keep what they
# load for the life of the process) are not ours.
export LSAN_OPTIONS="suppressions=$PWD/scripts/lsan.supp:print_suppressions=0"
export ASAN_OPTIONS="detect_leaks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
