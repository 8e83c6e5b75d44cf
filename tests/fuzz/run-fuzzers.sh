#!/usr/bin/env bash
# Builds the libFuzzer targets in build-fuzz (clang, ASan+UBSan) and runs each for a bounded time.
#
#   tests/fuzz/run-fuzzers.sh [SECONDS_PER_TARGET] [TARGET...]     (default 30 s; all five targets)
#
# Seeds: tests/fuzz/corpus/{npy,model,obj,specs} (small .npy files, models from `pmsc train` on a
# small set: version 1, version 2 with regions (with and without region keys), version 2 with
# learning and calibration sections,
# small OBJ meshes, and command-line texts), plus a few animated assets from Debian's assimp-testmodels for `skin`,
# copied at run time (each prefixed with the byte that picks its file extension, FuzzSkin.cpp).
# What the fuzzers add to the corpus stays in build-fuzz/corpus (not committed). A crash leaves
# build-fuzz/artifacts/<target>/crash-* and makes this script fail; the summary line per target
# gives executions, coverage (cov: edges, ft: features) and the corpus size.
#
# Environment: PMSC_FUZZ_JOBS (parallel build jobs, default nproc), PMSC_FUZZ_BUILD (default build-fuzz).
set -euo pipefail
cd "$(dirname "$0")/../.."

SECONDS_PER=${1:-30}
shift || true
TARGETS=("$@")
((${#TARGETS[@]})) || TARGETS=(npy model obj specs skin)
BUILD=${PMSC_FUZZ_BUILD:-build-fuzz}
JOBS=${PMSC_FUZZ_JOBS:-$(nproc)}
MODELS=/usr/share/assimp/models

CXX=$(command -v clang++ || command -v clang++-14) || { echo "run-fuzzers.sh: no clang++ (Debian: clang-14)" >&2; exit 1; }
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_CXX_COMPILER="$CXX" -DCMAKE_BUILD_TYPE=None \
  -DPMSC_BUILD_FUZZ=ON -DPMSC_BUILD_TESTS=OFF -DPMSC_BUILD_BENCH=OFF -DPMSC_BUILD_EXAMPLES=OFF \
  "${launcher[@]}" >/dev/null
cmake --build "$BUILD" -j "$JOBS" --target "${TARGETS[@]/#/fuzz_}"

# Skin seeds: the byte in front is the index of the extension in FuzzSkin.cpp's kExtensions.
seed_skin() {  # seed_skin INDEX FILE NAME
  [ -f "$2" ] || return 0
  { printf "\\x$(printf %02x "$1")"; cat "$2"; } >"$BUILD/seeds/skin/$3"
}
mkdir -p "$BUILD/seeds/skin"
seed_skin 2 "$MODELS/Collada/box_nested_animation.dae" box_nested_animation.dae
seed_skin 3 "$MODELS/glTF2/simple_skin/simple_skin.gltf" simple_skin.gltf
seed_skin 1 "$MODELS/X/test.x" test.x
if [ -f "$MODELS/BVH/01_01.bvh" ]; then  # the hierarchy and the first three frames of a mocap take
  { printf '\x00'; sed -n '1,185p' "$MODELS/BVH/01_01.bvh"; printf 'Frames: 3\nFrame Time: .0083333\n';
    sed -n '188,190p' "$MODELS/BVH/01_01.bvh"; } >"$BUILD/seeds/skin/01_01-3frames.bvh"
fi
morph=$MODELS/glTF2/glTF-Sample-Models/AnimatedMorphCube-glTF
if [ -f "$morph/AnimatedMorphCube.gltf" ]; then  # its buffer inlined, so the seed is one file
  { printf '\x03'; sed "s|\"AnimatedMorphCube.bin\"|\"data:application/octet-stream;base64,$(base64 -w0 "$morph/AnimatedMorphCube.bin")\"|" \
      "$morph/AnimatedMorphCube.gltf"; } >"$BUILD/seeds/skin/AnimatedMorphCube.gltf"
fi

# max_allocation_size_mb with allocator_may_return_null: an allocation of more than 4 GiB fails
# (std::bad_alloc) instead of being granted; -malloc_limit_mb above it keeps libFuzzer's own
# malloc limit from firing first. The skin target's importer runs in a forked child, where either
# ends that child only.
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:allocator_may_return_null=1:max_allocation_size_mb=4096}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$PWD/tests/fuzz/lsan.supp}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
# fuzz_one TARGET: one target for SECONDS_PER seconds; its summary line goes to $BUILD/fuzz-TARGET.line
# and its exit status says whether it found anything.
fuzz_one() {
  local t=$1 corpus=$BUILD/corpus/$1 seeds=tests/fuzz/corpus/$1 log=$BUILD/fuzz-$1.log result=clean status=0
  mkdir -p "$corpus" "$BUILD/artifacts/$t" "$BUILD/tmp/$t"
  [ "$t" = skin ] && seeds=$BUILD/seeds/skin
  : >"$log"
  # -timeout: an input slower than this is a hang; -rss_limit_mb: more memory is a failure.
  if ! TMPDIR=$(realpath -m "$BUILD/tmp/$t") "$BUILD/bin/fuzz_$t" "$corpus" "$seeds" -max_total_time="$SECONDS_PER" \
      -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=4097 -max_len=65536 -print_final_stats=1 \
      -artifact_prefix="$BUILD/artifacts/$t/" >"$log" 2>&1; then
    result="FAILED (see $log and $BUILD/artifacts/$t/)"
    status=1
  fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | awk '{n += $1} END {print n}')
  last=$(grep -E '^#[0-9]+' "$log" | tail -1 | grep -oE 'cov: [0-9]+ ft: [0-9]+ corp: [0-9]+/[^ ]+' || true)
  printf 'fuzz %-6s %6ss  %10s runs  %-40s %s\n' "$t" "$SECONDS_PER" "${runs:-?}" "${last:-?}" "$result" >"$BUILD/fuzz-$t.line"
  return $status
}

# JOBS targets at a time (each fuzzer is one process on one core), every one for its full time;
# the summary lines print in the targets' order.
status=0
pids=()
for t in "${TARGETS[@]}"; do
  while (($(jobs -rp | wc -l) >= JOBS)); do wait -n || true; done
  fuzz_one "$t" &
  pids+=($!)
done
for i in "${!TARGETS[@]}"; do
  wait "${pids[$i]}" || status=1
  cat "$BUILD/fuzz-${TARGETS[$i]}.line"
done
exit $status
