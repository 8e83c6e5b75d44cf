#!/usr/bin/env bash
# pmsc.sh — set up, build and run pmsc on Debian 12.
#
#   ./pmsc.sh demo       install missing Debian packages, build (Release), run the main demo
#   ./pmsc.sh test       same set-up, then the whole suite through ctest
#   ./pmsc.sh sanitize   unit tests under AddressSanitizer+UBSan, engine tests under ThreadSanitizer
#   ./pmsc.sh build      set-up and build only
#   ./pmsc.sh fuzz [S]   libFuzzer targets (clang, ASan+UBSan) in build-fuzz, S seconds each (default 30)
#
# Environment: PMSC_JOBS (default: nproc), PMSC_BUILD_DIR (default: build).
set -euo pipefail
cd "$(dirname "$0")"

JOBS=${PMSC_JOBS:-$(nproc)}
BUILD=${PMSC_BUILD_DIR:-build}

# Debian 12 packages the build, the tests and the examples need.
PACKAGES=(
  cmake ninja-build g++ ccache pkg-config
  libeigen3-dev libtbb-dev
  libopenvdb-dev libopenvdb-tools libboost-iostreams-dev libblosc-dev
  libembree-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  nlohmann-json3-dev libpng-dev
  libassimp-dev assimp-testmodels slurm-wlm munge
  libopenmpi-dev openmpi-bin  # issue 12: mpirun -n P pmsc train, srun --mpi=pmix
  python3 python3-dev python3-numpy pybind11-dev  # issue 13: the Python module (build/python) and its tests
)

# `./pmsc.sh fuzz` only: clang and its libFuzzer/sanitizer runtimes.
FUZZ_PACKAGES=(clang-14 libclang-rt-14-dev)

die() { echo "pmsc.sh: $*" >&2; exit 1; }

ensure_packages() {
  local missing=() p
  for p in "${PACKAGES[@]}" "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'ok installed' || missing+=("$p")
  done
  ((${#missing[@]} == 0)) && return 0
  [ "$(id -u)" = 0 ] || die "missing Debian packages (${missing[*]}); run as root or install them"
  echo "pmsc.sh: installing ${missing[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
}

# configure DIR [cmake args...]: Ninja + ccache so rebuilds on two cores stay short.
configure() {
  local dir=$1; shift
  cmake -S . -B "$dir" -G Ninja -DCMAKE_CXX_COMPILER_LAUNCHER=ccache "$@" >/dev/null
}

build_release() {
  configure "$BUILD" -DCMAKE_BUILD_TYPE=Release
  cmake --build "$BUILD" -j "$JOBS"
}

run_sanitizers() {
  # Unit tests (mathematics, file formats) under ASan+UBSan.
  configure build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPMSC_SANITIZE=address,undefined \
    -DPMSC_BUILD_EXAMPLES=OFF -DPMSC_BUILD_BENCH=OFF
  cmake --build build-asan -j "$JOBS" --target pmsc_unit_tests pmsc_io_tests
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir build-asan -L unit --output-on-failure -j "$JOBS"
  # The engine's tests under ThreadSanitizer.
  if [ -d engine ] && grep -q pmsc_engine_tests tests/engine/CMakeLists.txt 2>/dev/null; then
    configure build-tsan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPMSC_SANITIZE=thread \
      -DPMSC_BUILD_EXAMPLES=OFF -DPMSC_BUILD_BENCH=OFF
    cmake --build build-tsan -j "$JOBS" --target pmsc_engine_tests
    TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1 \
      ctest --test-dir build-tsan -L engine --output-on-failure -j "$JOBS"
  fi
}

cmd=${1:-}
case "$cmd" in
  demo)
    ensure_packages; build_release
    shift; exec "$BUILD/bin/pmsc" demo "$@" ;;
  test)
    ensure_packages; build_release
    ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" ;;
  sanitize)
    ensure_packages; run_sanitizers ;;
  build)
    ensure_packages; build_release ;;
  fuzz)
    ensure_packages "${FUZZ_PACKAGES[@]}"
    PMSC_FUZZ_JOBS=$JOBS exec tests/fuzz/run-fuzzers.sh "${2:-30}" ;;
  *)
    echo "usage: ./pmsc.sh demo|test|sanitize|build|fuzz [seconds]" >&2; exit 2 ;;
esac
