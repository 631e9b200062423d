#!/bin/sh
# Installs ARPos's build dependencies (Debian 12 packages) and builds it.
# Re-running is quick: apt is skipped when every package is present, and the
# build is incremental (ccache is used when present).
#   tools/setup.sh            install + build into ./build
#   BUILD_DIR=dir tools/setup.sh
set -eu
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}

PACKAGES="build-essential cmake ninja-build ccache pkg-config git
  qtbase5-dev libvtk9-dev libvtk9-qt-dev libopencv-dev libopencv-contrib-dev
  libpcl-dev libeigen3-dev libsqlite3-dev sqlite3 libssl-dev libassimp-dev libceres-dev
  libgtest-dev libgmock-dev libbenchmark-dev libyaml-cpp-dev
  libgdcm-dev libvtkgdcm-dev
  libopenni2-dev libopenigtlink-dev openigtlink-examples
  xvfb xauth libgl1-mesa-dri"

missing=""
for p in $PACKAGES; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing="$missing $p"
  fi
done
if [ -n "$missing" ]; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO=sudo
  echo "setup: installing$missing"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends $missing
fi

if [ ! -f "$BUILD_DIR/build.ninja" ]; then
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release
fi
# Two jobs: the machines have 2 cores and PCL translation units need ~1 GB each.
cmake --build "$BUILD_DIR" -j "${JOBS:-2}"
echo "setup: built $BUILD_DIR/bin/arpos"
