#!/usr/bin/env bash
# pmsc.sh — set up, build and run pmsc on Debian 12.
#
#   ./pmsc.sh demo       install missing Debian packages, build the program (Release), run the main demo
#   ./pmsc.sh test       same set-up, then the whole suite through ctest: the fast tiers (unit, cli)
#                        first, so a broken change fails in minutes, then everything else (the
#                        browser test of `pmsc view` among them: label browser); the benchmarks
#                        are not built (`build` and `tidy` build them)
#   ./pmsc.sh format     check that every .h/.cpp matches .clang-format (--fix rewrites them)
#   ./pmsc.sh tidy       clang-tidy (.clang-tidy) on the product code that has no heavy headers
#   ./pmsc.sh sanitize   unit tests under AddressSanitizer+UBSan, engine tests under ThreadSanitizer
#   ./pmsc.sh build      set-up and build only
#   ./pmsc.sh package    a Debian package (.deb) of a portable build (no -march=native) in build-package
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
  libcli11-dev  # the TOML/INI reader of every command's --config FILE
  libboost-dev  # Boost.Beast and Asio: the HTTP/WebSocket server of pmsc view
  libassimp-dev assimp-testmodels slurm-wlm munge
  libopenmpi-dev openmpi-bin  # mpirun -n P pmsc train, srun --mpi=pmix
  python3 python3-dev python3-numpy pybind11-dev  # the Python module (build/python) and its tests
)

# `pmsc view`'s page: Node.js's npm fetches its packages (three.js). npm comes with the machine's
# Node.js; Debian's npm package is added only where there is none.
WEB_PACKAGES=(nodejs)
# The page's headless-browser test (ctest label browser, `./pmsc.sh test` only): Debian's Chromium
# renders the page (WebGL through SwiftShader).
BROWSER_PACKAGES=(chromium)

# Blender as the calculation (ctest label blender, `./pmsc.sh test` only): Debian's Blender runs
# headless as an exec child; its Python is the system python3 with numpy, and OpenVDB's Python
# module reads `pmsc run --format vdb` caches back into it (docs/blender.md).
BLENDER_PACKAGES=(blender python3-openvdb)

# `./pmsc.sh fuzz` only: clang and its libFuzzer/sanitizer runtimes.
FUZZ_PACKAGES=(clang-14 libclang-rt-14-dev)
# `./pmsc.sh format` and `./pmsc.sh tidy`.
STYLE_PACKAGES=(clang-format-14 clang-tidy-14)

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
  # The lock timeout: a `test` whose build failed leaves its background installation (below) running.
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600 \
    "${missing[@]}" >/dev/null
}

# The page's npm packages (three, puppeteer-core: pinned in web/viewer/package-lock.json) from the
# npm registry, when node_modules is missing or older than the lock file. puppeteer-core downloads
# no browser; the test drives /usr/bin/chromium.
ensure_web() {
  ensure_packages "${WEB_PACKAGES[@]}"
  if ! command -v npm >/dev/null; then ensure_packages npm; fi
  local web=web/viewer
  if [ ! -f "$web/node_modules/.package-lock.json" ] || [ "$web/package-lock.json" -nt "$web/node_modules/.package-lock.json" ]; then
    echo "pmsc.sh: npm ci in $web"
    (cd "$web" && PUPPETEER_SKIP_DOWNLOAD=1 npm ci --no-audit --no-fund --loglevel=error)
    touch "$web/node_modules/.package-lock.json"
  fi
}

# What only the tests need (Blender, Chromium, Node.js and the page's npm packages: most of the
# set-up on a fresh machine, and downloads and unpacking rather than computing) installs in the
# background while the build keeps both cores busy; test_setup_wait joins it before the tests that
# use it. Nothing the build compiles or links comes from it.
SETUP_PID=
test_setup_start() {
  mkdir -p "$BUILD"
  (ensure_packages "${BROWSER_PACKAGES[@]}" "${BLENDER_PACKAGES[@]}"; ensure_web) >"$BUILD/test-setup.log" 2>&1 &
  SETUP_PID=$!
}
test_setup_wait() {
  wait "$SETUP_PID" || {
    tail -n 5 "$BUILD/test-setup.log" >&2
    die "installing what the tests need (Blender, Chromium, the page's npm packages) failed; log: $BUILD/test-setup.log"
  }
  cat "$BUILD/test-setup.log"
}

# require_disk GB: fail at once, in one line, when the checkout's file system has less than GB free.
# `test` holds about 0.5 GB of Release build, 1 GB of sanitizer builds and under 1 GB of test
# outputs at a time (the novelty suites delete each set's frames once measured); a disk that fills
# mid-run fails tests one by one with "No space left on device" instead.
require_disk() {
  local free_kb
  free_kb=$(df -Pk . | awk 'NR == 2 { print $4 }')
  [ -n "$free_kb" ] || return 0
  ((free_kb >= $1 * 1024 * 1024)) || die "$((free_kb / 1024)) MB free on $(df -P . | awk 'NR == 2 { print $6 }'); './pmsc.sh $cmd' needs $1 GB (builds and test outputs)"
}

# configure DIR [cmake args...]: Ninja + ccache so rebuilds on two cores stay short. The build runs
# on the machine that built it, so it is tuned for it (PMSC_NATIVE; installs and packages are not).
configure() {
  local dir=$1; shift
  cmake -S . -B "$dir" -G Ninja -DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache -DPMSC_NATIVE=ON \
    -DCMAKE_EXPORT_COMPILE_COMMANDS=ON "$@" >/dev/null
}

# ccache keys on paths relative to the checkout, so a fresh clone elsewhere (CI) reuses the cache.
export CCACHE_BASEDIR="$PWD" CCACHE_NOHASHDIR=true

# build_release [TARGET...]: the Release build, of the targets given or of everything. BENCH=OFF
# leaves the Google Benchmark suites out: `test` runs none of them, and their 11 translation units
# are 91 s of compiler time on an empty cache (.ninja_log); `tidy`, the next tier of .ci/run, builds
# them, so CI still compiles every target.
build_release() {
  configure "$BUILD" -DCMAKE_BUILD_TYPE=Release "-DPMSC_BUILD_BENCH=${BENCH:-ON}"
  if [ $# -gt 0 ]; then cmake --build "$BUILD" -j "$JOBS" --target "$@"; else cmake --build "$BUILD" -j "$JOBS"; fi
}

# Every tracked .h/.cpp/.c against .clang-format; one line per file that differs.
check_format() {
  local files bad
  mapfile -t files < <(git ls-files '*.h' '*.cpp' '*.c')
  if [ "${1:-}" = --fix ]; then clang-format-14 -i "${files[@]}"; return 0; fi
  bad=$(clang-format-14 --dry-run "${files[@]}" 2>&1 | grep -oE '^[^:]+\.(h|cpp|c):' | sort -u | tr -d ':') || true
  [ -z "$bad" ] || die "these files differ from .clang-format (./pmsc.sh format --fix): $(echo $bad)"
  echo "pmsc.sh: ${#files[@]} files match .clang-format"
}

# clang-tidy on the product translation units that include no OpenVDB, Embree, Assimp or Beast (those
# cost ~25 s each to parse; the checks that matter for them run on the rest of their library).
# tools/tidy_batched.py checks the files of one target in a few translation units, so Eigen's and
# the standard library's headers are walked once a batch instead of once a file: 2.3 minutes on 2
# cores where one clang-tidy a file takes 11.
run_tidy() {
  local files
  mapfile -t files < <(git ls-files 'pmsc/*.cpp' 'nodes/*.cpp' 'engine/*.cpp' 'app/*.cpp' 'capi/*.cpp' 'cli/*.cpp' \
    'evaluators/*.cpp' 'viewer/*.cpp' | xargs grep -LE '#include <(openvdb|embree3|assimp|boost/beast)/')
  python3 tools/tidy_batched.py --build "$BUILD" --jobs "$JOBS" "${files[@]}" >"$BUILD/clang-tidy.log" 2>&1 \
    || { grep -E 'warning:|error:' "$BUILD/clang-tidy.log" | sort -u | head -50; die "clang-tidy found problems (full log: $BUILD/clang-tidy.log)"; }
  echo "pmsc.sh: clang-tidy clean on ${#files[@]} files"
}

# The sanitizer builds' flags: -O1 (the level both sanitizers' manuals advise) and line tables only
# (-g1: the reports name file and line, and no debugger reads these builds). Why not RelWithDebInfo's
# -O2 -g: they compile in about half the time (pmsc/Training.cpp under ASan+UBSan: 13.6 s against
# 28.7 s), and the two builds are what an empty compiler cache makes CI wait for.
SANITIZE_FLAGS=(-DCMAKE_BUILD_TYPE=RelWithDebInfo "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG"
  "-DCMAKE_C_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DPMSC_BUILD_EXAMPLES=OFF -DPMSC_BUILD_BENCH=OFF)

run_sanitizers() {
  # Unit tests (mathematics, file formats, the C API) under ASan+UBSan.
  configure build-asan "${SANITIZE_FLAGS[@]}" -DPMSC_SANITIZE=address,undefined
  cmake --build build-asan -j "$JOBS" --target pmsc_unit_tests pmsc_io_tests pmsc_app_tests pmsc_capi_test_model pmsc_capi_bad_inputs
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --test-dir build-asan -L unit --output-on-failure -j "$JOBS"
  # The engine's tests and pmsc view's session and server (threads of their own around the
  # engine) under ThreadSanitizer.
  if [ -d engine ] && grep -q pmsc_engine_tests tests/engine/CMakeLists.txt 2>/dev/null; then
    configure build-tsan "${SANITIZE_FLAGS[@]}" -DPMSC_SANITIZE=thread
    cmake --build build-tsan -j "$JOBS" --target pmsc_engine_tests pmsc_nodes_tests pmsc_viewer_tests
    # A oneTBB worker can end inside the uninstrumented libtbb after a test passed, which
    # ThreadSanitizer reports as "finished with ignores enabled" (no race, no test failure of
    # its own). Such a test runs once more; any other report fails the suite.
    local log=build-tsan/Testing/Temporary/LastTest.log
    if ! TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1 \
      ctest --test-dir build-tsan -L '^(engine|viewer)$' --output-on-failure -j "$JOBS"; then
      grep -q "finished with ignores enabled" "$log" && ! grep -qE "WARNING: ThreadSanitizer|FAILED  \]" "$log" ||
        die "ThreadSanitizer failed the engine or viewer tests (see $log)"
      echo "pmsc.sh: a oneTBB worker ended with ThreadSanitizer's ignores enabled; running that test again"
      TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1 \
        ctest --test-dir build-tsan -L '^(engine|viewer)$' --rerun-failed --output-on-failure -j "$JOBS"
    fi
  fi
}

cmd=${1:-}
case "$cmd" in
  demo)
    # The program and its demos only (31 of the build's 77 unity batches: 4 min 11 s on 2 cores
    # without a compiler cache, where everything takes 7 min 18 s): the tests, benchmarks, Python
    # module and fuzz targets come with `test`.
    ensure_packages; ensure_web; build_release pmsc
    shift; exec "$BUILD/bin/pmsc" demo "$@" ;;
  test)
    require_disk 3
    ensure_packages "${STYLE_PACKAGES[@]}"; test_setup_start; check_format; BENCH=OFF build_release
    ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" -L '^(unit|cli)$'
    test_setup_wait
    ctest --test-dir "$BUILD" --output-on-failure -j "$JOBS" -LE '^(unit|cli)$' ;;
  format)
    ensure_packages "${STYLE_PACKAGES[@]}"; check_format "${2:-}" ;;
  tidy)
    ensure_packages "${STYLE_PACKAGES[@]}"; build_release; run_tidy ;;
  sanitize)
    ensure_packages; run_sanitizers ;;
  build)
    ensure_packages; ensure_web; build_release ;;
  package)
    ensure_packages dpkg-dev
    cmake -S . -B build-package -G Ninja -DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_BUILD_TYPE=Release \
      -DCMAKE_INSTALL_PREFIX=/usr -DPMSC_NATIVE=OFF -DPMSC_BUILD_TESTS=OFF -DPMSC_BUILD_BENCH=OFF >/dev/null
    cmake --build build-package -j "$JOBS"
    (cd build-package && cpack -G DEB) ;;
  fuzz)
    ensure_packages "${FUZZ_PACKAGES[@]}"
    PMSC_FUZZ_JOBS=$JOBS exec tests/fuzz/run-fuzzers.sh "${2:-30}" ;;
  *)
    echo "usage: ./pmsc.sh demo|test|sanitize|build|format [--fix]|tidy|package|fuzz [seconds]" >&2; exit 2 ;;
esac
