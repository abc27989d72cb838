#!/usr/bin/env bash
# SPDX-License-Identifier: BSD-3-Clause
# One entry point for a fresh Debian 12 machine: installs the missing Debian packages, configures
# and builds, then does what was asked.
#   scripts/setup.sh demo    set up, build the model set, run the main job (configs/demo.toml) for a few seconds
#   scripts/setup.sh test    set up, build the model set, run every test suite (and sanitizer builds)
#   scripts/setup.sh build   set up and build only
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-build}"
case "$mode" in demo|test|build) ;; -h|--help) sed -n '2,7p' "$0"; exit 0 ;;
  *) echo "usage: scripts/setup.sh demo|test|build" >&2; exit 2 ;; esac

# Build and test dependencies, all Debian packages (no downloads at build time beyond apt).
packages=(g++ meson ninja-build pkg-config
          libeigen3-dev libassimp-dev libzmq3-dev libsodium-dev cppzmq-dev
          doctest-dev libtomlplusplus-dev libcli11-dev libsystemd-dev libfcl-dev systemd
          clang libclang-rt-14-dev   # clang + libFuzzer runtime: tests/fuzz/run_fuzz.sh
          clang-format               # scripts/format.sh --check
          doxygen                    # scripts/check_docs.sh: the API reference of the installed headers
          cmake                      # tests/install: a CMake consumer of the installed package
          pybind11-dev python3-dev python3-numpy   # the Python module (python/)
          python3-mesonpy patchelf python3-venv mypy  # pip install . (pyproject.toml), its stubs checked
          libcivetweb-dev libjs-three              # the live view (spheretouch run --view)
          nlohmann-json3-dev                       # JSON: the view's page reports, the benchmarks' output
          chromium)                                # the live view's browser tests (headless)
missing=()
for p in "${packages[@]}"; do
  [[ "$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null)" == *"install ok installed"* ]] || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  sudo=""; [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

jobs="${ST_JOBS:-2}"
if [ ! -f build/build.ninja ]; then
  meson setup build --buildtype=release
fi
ninja -C build -j"$jobs"

case "$mode" in
  build) ;;
  demo)
    scripts/models.sh
    models="${ST_MODEL_DIR:-.cache/models}"
    build/spheretouch info "$models"/hand_L2.off "$models"/elephant.off "$models"/armadillo_L1.off \
      "$models"/armadillo_L2.off "$models"/bunny.off
    # The main job on the embedded default: the hand touches the elephant with in-process workers.
    build/spheretouch run configs/demo.toml --duration "${ST_DEMO_SECONDS:-6}"
    ;;
  test)
    scripts/models.sh
    scripts/run_tests.sh
    ;;
esac
