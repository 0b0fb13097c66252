#!/usr/bin/env bash
# Build the ament_cmake package suspension_tuning_interfaces against the ROS 2 Jazzy
# wheels in a virtual environment and install it into that environment.
#   usage: scripts/build_interfaces.sh <venv> [build dir]
# The generated Python package lands in the venv's site-packages and its shared
# libraries in <venv>/lib, where the wheels' start-up hook puts them on
# LD_LIBRARY_PATH (see ../shared/notes/ros2-from-pypi.md).
set -euo pipefail
venv=$(cd "$1" && pwd)
build=${2:-build/interfaces}
here=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$build"
export PATH="$venv/bin:$PATH"
export CMAKE_PREFIX_PATH="$venv"
export AMENT_PREFIX_PATH="$venv"
cmake -S "$here/suspension_tuning_interfaces" -B "$build" \
  -DCMAKE_BUILD_TYPE=Release \
  -DBUILD_TESTING=OFF \
  -DPython3_EXECUTABLE="$venv/bin/python" \
  -DCMAKE_INSTALL_PREFIX="$venv" >"$build.log" 2>&1 || { cat "$build.log"; exit 1; }
cmake --build "$build" -j2 >>"$build.log" 2>&1 || { tail -50 "$build.log"; exit 1; }
cmake --install "$build" >>"$build.log" 2>&1 || { tail -50 "$build.log"; exit 1; }
echo "suspension_tuning_interfaces installed into $venv (log: $build.log)"
