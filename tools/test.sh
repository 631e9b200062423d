#!/bin/sh
# Runs the whole default test suite (everything but the `long` label) after
# tools/setup.sh. Tests that open windows run under Xvfb with Mesa's software GL.
#   tools/test.sh              default suite
#   tools/test.sh -L long      long benchmarks and large simulated cases
set -eu
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
if [ $# -eq 0 ]; then
  set -- -LE long
fi
export LIBGL_ALWAYS_SOFTWARE=1
export QT_X11_NO_MITSHM=1
cd "$BUILD_DIR"
exec xvfb-run -a -s "-screen 0 1280x1024x24" ctest --output-on-failure -j "${JOBS:-2}" "$@"
