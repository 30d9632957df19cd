#!/usr/bin/env bash
# Installs the Debian 12 packages FlareKit needs (idempotent), then configures and builds a
# Release build in build/.
#
#   scripts/setup.sh            packages + Release build in build/
#   scripts/setup.sh --no-build packages only
#
# Environment: FLAREKIT_BUILD_DIR (default build), FLAREKIT_BUILD_TYPE (default Release),
# FLAREKIT_CMAKE_ARGS (extra arguments for cmake, e.g. -DFLAREKIT_SANITIZE=ON).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)

# Exactly what the project uses; each line says which part needs it.
packages=(
  build-essential cmake ninja-build pkgconf   # toolchain
  libopencv-dev                               # images, filters, detection (all layers)
  libceres-dev libeigen3-dev                  # fitting (fit/)
  libopenexr-dev libimath-dev openexr         # EXR I/O (common/), exrheader for the tests
  libtbb-dev                                  # threads
  libgpiod-dev                                # GPIO stepper head (acquisition/)
  libusb-1.0-0-dev                            # Pololu Tic head (acquisition/)
  libgphoto2-dev libraw-dev libtiff-dev       # tethered camera, RAW decoding, DNG test files
  libcli11-dev nlohmann-json3-dev libtomlplusplus-dev
  libgtest-dev libgmock-dev libbenchmark-dev  # tests and benchmarks
  libumockdev-dev umockdev                    # driver tests without hardware
  libtinygltf-dev                             # glTF scenes (predict/)
  chromium                                    # the report's browser test (predict/)
  jq                                          # bench/fit_accuracy.sh
  clang libclang-rt-14-dev                    # scripts/fuzz.sh (libFuzzer, ASan/UBSan runtimes)
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if ((${#missing[@]})); then
  if [[ $(id -u) -ne 0 ]]; then
    if command -v sudo >/dev/null 2>&1; then
      SUDO=sudo
    else
      echo "setup.sh: ${#missing[@]} packages are missing (${missing[*]}); run this script as root" >&2
      exit 1
    fi
  else
    SUDO=
  fi
  echo "setup.sh: installing ${#missing[@]} Debian packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "setup.sh: all ${#packages[@]} Debian packages present"
fi

[[ ${1:-} == --no-build ]] && exit 0

build_dir=${FLAREKIT_BUILD_DIR:-$here/build}
build_type=${FLAREKIT_BUILD_TYPE:-Release}
# shellcheck disable=SC2086
cmake -S "$here" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE="$build_type" ${FLAREKIT_CMAKE_ARGS:-} >/dev/null
cmake --build "$build_dir" -j"$(nproc)"
echo "setup.sh: built $build_dir/bin/flarekit"
