#!/usr/bin/env bash
# Generate the vendored interface packages (interfaces/*: simulation_interfaces, control_msgs' cut) with rosidl
# from the index's wheels and install them into the venv, so that `from simulation_interfaces.srv import ...`
# works there with no environment variables. Called by `make` (the venv's .interfaces stamp); inside a ROS 2
# install the distribution's packages are used instead (package.xml <depend>; interfaces/COLCON_IGNORE).
#
# usage: tools/build_interfaces.sh VENV BUILD_DIR PACKAGE...
set -euo pipefail

venv=$(realpath "$1")
build=$2
shift 2
py=$venv/bin/python

# One clear error when a tool is missing, rather than a CMake trace half-way.
missing=()
command -v cmake >/dev/null || missing+=(cmake)
command -v cc >/dev/null || command -v gcc >/dev/null || missing+=(gcc)
command -v c++ >/dev/null || command -v g++ >/dev/null || missing+=(g++)
generator=()
if command -v ninja >/dev/null; then generator=(-G Ninja); else command -v make >/dev/null || missing+=(make); fi
if ((${#missing[@]})); then
    echo "error: building the ROS interface packages (interfaces/) into $venv needs cmake (>= 3.16), a C and a" >&2
    echo "       C++ compiler and make (or ninja); missing: ${missing[*]}. On Debian/Ubuntu:" >&2
    echo "           sudo apt-get install cmake gcc g++ make" >&2
    exit 2
fi

# The wheels' installed CMake files name the wheel builder's Python and numpy include directories: point
# them at this venv's (idempotent: nothing is left to replace the second time).
pyinc=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
npinc=$("$py" -c "import numpy; print(numpy.get_include())")
{ grep -rl /opt/python/cp3 "$venv/share" --include='*.cmake' || true; } | xargs -r sed -i -E \
    -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/include/python3\.[0-9]+#$pyinc#g" \
    -e "s#/opt/python/cp3[0-9]+-cp3[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$npinc#g"

export AMENT_PREFIX_PATH=$venv
jobs=$(nproc 2>/dev/null || echo 2)
mkdir -p "$build"
for pkg in "$@"; do
    echo "building ROS interface package $pkg (rosidl, into $venv) ..."
    # no CMAKE_BUILD_TYPE: the generated (de)serializers of a few small messages gain nothing from -O2
    rm -rf "${build:?}/$pkg"
    cmake "${generator[@]}" -S "interfaces/$pkg" -B "$build/$pkg" -DBUILD_TESTING=OFF \
        -DCMAKE_PROJECT_INCLUDE="$PWD/interfaces/c_only.cmake" \
        -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$py" >"$build/$pkg.log" 2>&1 \
        && cmake --build "$build/$pkg" -j "$jobs" >>"$build/$pkg.log" 2>&1 \
        && cmake --install "$build/$pkg" >>"$build/$pkg.log" 2>&1 \
        || { echo "error: building $pkg failed; the last lines of $build/$pkg.log:" >&2; tail -n 30 "$build/$pkg.log" >&2; exit 1; }
done
