#!/usr/bin/env bash
# Sets up (packages + build) and runs the whole test suite.
#
#   scripts/test.sh             Release build in build/, all tests
#   scripts/test.sh --sanitize  AddressSanitizer + UndefinedBehaviorSanitizer build in build-asan/
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

if [[ ${1:-} == --sanitize ]]; then
  export FLAREKIT_BUILD_DIR=$here/build-asan
  export FLAREKIT_BUILD_TYPE=RelWithDebInfo
  export FLAREKIT_CMAKE_ARGS="-DFLAREKIT_SANITIZE=ON -DFLAREKIT_BUILD_BENCHMARKS=OFF"
  export ASAN_OPTIONS=detect_leaks=1:verify_asan_link_order=0
  export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
fi
build_dir=${FLAREKIT_BUILD_DIR:-$here/build}

"$here/scripts/setup.sh"
ctest --test-dir "$build_dir" --output-on-failure -j"$(nproc)" --timeout 900
