#!/usr/bin/env bash
# Set up the workspace on a fresh machine, idempotently:
#   1. a virtual environment with the pinned dependencies (ROS 2 Jazzy wheels
#      from PyPI, numpy, pybullet, ...), reinstalled only when requirements.txt
#      or the venv's interpreter changes;
#   2. the ROS wheels' CMake export files pointed at this interpreter (they carry
#      the wheel build machine's include paths, /opt/python/cpXY-cpXY/...);
#   3. colcon build of src/ into the workspace (build/install/log), only when a
#      package manifest, setup file or interface changed (--symlink-install: edits
#      to Python modules need no rebuild);
#   4. <workspace>/env.sh, the <venv>/bin/holonomic-* wrappers that source it,
#      and a .pth file so that the venv's python imports the packages unsourced.
# A step's "done" stamp is written only after the step succeeded: the next run
# redoes a failed step.
#
# Usage: scripts/setup.sh [--force]
# Environment: PYTHON  interpreter for a new venv (default python3; a pyenv
#                      shim that does not run is resolved to pyenv's own copy)
#              VENV    the virtual environment (default <repo>/.venv)
#              WS      the colcon workspace (default <repo>/ros2_ws)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
absolute() { case "$1" in /*) printf '%s' "$1";; *) printf '%s/%s' "$ROOT" "$1";; esac; }
VENV="$(absolute "${VENV:-.venv}")"
WS="$(absolute "${WS:-ros2_ws}")"
PYTHON_FROM_USER="${PYTHON:+1}"
PYTHON="${PYTHON:-python3}"
FORCE=0
[[ "${1:-}" == "--force" ]] && FORCE=1

log() { printf 'setup: %s\n' "$*" >&2; }
fail() { log "FAILED: $*"; exit 1; }

# One set-up at a time per workspace: two concurrent `make test` runs would
# otherwise pip-install and colcon-build into the same folders.
mkdir -p "$WS"
exec 9>"$WS/.setup.lock"
flock 9

hash_of() { sha256sum "$@" | sha256sum | cut -d' ' -f1; }
version_of() { "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])'; }

# An interpreter that runs: "python3.12" may be a pyenv shim that fails when
# no pyenv version is selected; then take pyenv's (or the system's) python3.12.
resolve_python() {
    local want="$1" name candidate
    if "$want" -c 'import sys' >/dev/null 2>&1; then printf '%s' "$want"; return; fi
    name="$(basename "$want")"
    for candidate in "$(pyenv root 2>/dev/null || echo "${HOME:-/root}/.pyenv")"/versions/*/bin/"$name" \
            /usr/bin/"$name" /usr/local/bin/"$name"; do
        if [[ -x "$candidate" ]] && "$candidate" -c 'import sys' >/dev/null 2>&1; then
            log "$want does not run here; using $candidate"
            printf '%s' "$candidate"; return
        fi
    done
    return 1
}

# -- 1. virtual environment ---------------------------------------------------
if [[ ! -x "$VENV/bin/python" ]]; then
    PY="$(resolve_python "$PYTHON")" || fail "PYTHON=$PYTHON does not run, and no working \
$(basename "$PYTHON") is in pyenv's versions, /usr/bin or /usr/local/bin: set PYTHON to an interpreter's path"
    "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
        || fail "$PY is Python $(version_of "$PY"); the ROS 2 Jazzy wheels need 3.11 or newer"
    log "creating $VENV with $PY (Python $(version_of "$PY"))"
    "$PY" -m venv "$VENV" || { rm -rf "$VENV"; fail "step 1 (python -m venv $VENV)"; }
elif [[ -n "$PYTHON_FROM_USER" ]] && WANT="$(resolve_python "$PYTHON")" \
        && [[ "$(version_of "$WANT")" != "$(version_of "$VENV/bin/python")" ]]; then
    # `PYTHON=python3.12 make test` in a checkout set up with another Python
    fail "$VENV is Python $(version_of "$VENV/bin/python"), PYTHON=$PYTHON is $(version_of "$WANT"): \
run \`make clean\` first, or give the other Python its own VENV=... WS=..."
fi
# content and interpreter, not the checkout's path (a venv may serve a copy)
REQ_HASH="$(cd "$ROOT" && hash_of requirements.txt)-py$(version_of "$VENV/bin/python")"
if [[ $FORCE == 1 || "$(cat "$VENV/.requirements.sha256" 2>/dev/null)" != "$REQ_HASH" ]]; then
    rm -f "$VENV/.requirements.sha256" "$WS/.build.sha256"
    log "installing pinned dependencies into $VENV (about a minute; on Python 3.12 and 3.13" \
        "pip first compiles pybullet, several minutes the first time)"
    # The machine's pip config points at local mirrors; their "Location ... is
    # ignored" notices are noise.
    "$VENV/bin/python" -m pip install --disable-pip-version-check -q -r "$ROOT/requirements.txt" \
        2> >(grep -v 'is ignored' >&2) \
        || fail "step 1 (pip install -r requirements.txt into $VENV): pip's messages are above"
    echo "$REQ_HASH" > "$VENV/.requirements.sha256"
fi

# -- 2. CMake export files of the ROS wheels ----------------------------------
# On every run (idempotent, a fraction of a second), so that no interrupted or
# failed run can leave an unfixed file behind for the next one to skip.
"$VENV/bin/python" "$ROOT/scripts/fix_cmake_exports.py" "$VENV" \
    || fail "step 2 (pointing the ROS wheels' CMake export files at $VENV/bin/python)"

# -- 3. colcon build ------------------------------------------------------------
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
export PATH="$VENV/bin:$PATH"
export HOME="${HOME:-$ROOT}"

SKIP=()
# tf2_msgs is built here only where the system does not provide it (a full ROS
# install sourced before running make): two copies would shadow each other.
if "$VENV/bin/python" -c 'import tf2_msgs.msg' 2>/dev/null \
        && [[ "$("$VENV/bin/python" -c 'import tf2_msgs, os; print(os.path.realpath(tf2_msgs.__file__))')" != "$WS"/* ]]; then
    log "tf2_msgs provided by the system: not building it"
    SKIP=(--packages-skip tf2_msgs)
fi

BUILD_INPUTS=$(cd "$ROOT" && find src -name package.xml -o -name setup.py -o -name setup.cfg \
    -o -name CMakeLists.txt -o -name '*.msg' -o -name '*.c' -o -name __init__.py -o -path 'src/*/resource/*' | sort)
BUILD_HASH="$(cd "$ROOT" && { echo "$BUILD_INPUTS"; echo "${SKIP[*]:-}"; ls config; } | sha256sum | cut -d' ' -f1)"
BUILD_HASH="$BUILD_HASH-$(cd "$ROOT" && hash_of $BUILD_INPUTS)"
if [[ $FORCE == 1 || "$(cat "$WS/.build.sha256" 2>/dev/null)" != "$BUILD_HASH" || ! -d "$WS/install" ]]; then
    rm -f "$WS/.build.sha256"
    log "building the workspace into $WS"
    if ! (cd "$ROOT" && "$VENV/bin/colcon" --log-base "$WS/log" build --symlink-install \
        --base-paths src --build-base "$WS/build" --install-base "$WS/install" \
        --event-handlers console_direct- console_stderr- summary+ "${SKIP[@]}" \
        --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VENV/bin/python" \
        -DPYTHON_EXECUTABLE="$VENV/bin/python" > "$WS/colcon_build.log" 2>&1); then
        # colcon's summary names the failed packages ("Failed   <<< tf2_msgs");
        # each one's own log holds the compiler's or CMake's words.
        failed=$(sed -n 's/^Failed *<<< *\([^ ]*\).*/\1/p' "$WS/colcon_build.log")
        shown=0
        for pkg in $failed; do
            pkg_log="$WS/log/latest_build/$pkg/stdout_stderr.log"
            [[ -s "$pkg_log" ]] || continue
            log "the lines that matter in $pkg_log:"
            { grep -n -A4 -E 'CMake Error|[Ee]rror:|Traceback' "$pkg_log" | head -n 40 \
                || tail -n 25 "$pkg_log"; } | sed 's/^/    /' >&2
            shown=1
        done
        if [[ $shown == 0 ]]; then     # colcon itself failed (e.g. a missing dependency)
            log "the end of $WS/colcon_build.log:"
            tail -n 25 "$WS/colcon_build.log" | sed 's/^/    /' >&2
        fi
        fail "step 3 (colcon build of src/)${failed:+ in package(s): $failed}; full logs in $WS/log/latest_build"
    fi
    echo "$BUILD_HASH" > "$WS/.build.sha256"
fi

# -- 4. environment file and wrappers -----------------------------------------
cat > "$WS/env.sh" <<EOF
# Generated by scripts/setup.sh: the environment of the built workspace.
# Source it (bash/sh) to use the workspace's packages from this shell.
_ws="$WS"
_venv="$VENV"
export PATH="\$_venv/bin\${PATH:+:\$PATH}"
# colcon's own environment of the workspace (PYTHONPATH incl. the symlinked
# develop packages, LD_LIBRARY_PATH of tf2_msgs, AMENT_PREFIX_PATH) ...
COLCON_CURRENT_PREFIX="\$_ws/install" . "\$_ws/install/local_setup.sh"
# ... plus the virtual environment, where the ROS wheels keep their share/.
case ":\${AMENT_PREFIX_PATH:-}:" in *":\$_venv:"*) ;; *) export AMENT_PREFIX_PATH="\${AMENT_PREFIX_PATH:+\$AMENT_PREFIX_PATH:}\$_venv";; esac
# DDS discovery stays on this machine unless the user chose otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE="\${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
# rclpy needs HOME or ROS_LOG_DIR for its logging.
[ -n "\${HOME:-}" ] || export ROS_LOG_DIR="\${ROS_LOG_DIR:-\$_ws/log/ros}"
unset _ws _venv
EOF

# Every package's holonomic-* console script gets a wrapper on .venv/bin. The
# wrapper calls the entry point's function directly (read from the packages'
# entry_points.txt): the generated console script would first scan every
# installed distribution's metadata, a tenth of a second in which a Ctrl-C
# lands as a KeyboardInterrupt instead of reaching the program's own handler.
"$VENV/bin/python" - "$WS" <<'PY' | while read -r name target; do
import configparser, pathlib, sys
ws = pathlib.Path(sys.argv[1])
for path in sorted(ws.glob("build/*/*.egg-info/entry_points.txt")):
    parser = configparser.ConfigParser()
    parser.read(path)
    if parser.has_section("console_scripts"):
        for name, target in parser.items("console_scripts"):
            if name.startswith("holonomic-"):
                print(name, target.replace(" ", ""))
PY
    module="${target%%:*}"
    func="${target#*:}"
    cat > "$VENV/bin/$name" <<EOF
#!/usr/bin/env bash
# Generated by scripts/setup.sh: run $name ($target) in the built workspace's
# environment. A SIGINT/SIGTERM while the environment loads ends the program
# before it has started anything: exit 0, as after a normal shutdown. From
# its first line the Python program handles them itself.
trap 'exit 0' INT TERM
. "$WS/env.sh"
trap - INT TERM
exec "$VENV/bin/python" -c 'import sys; sys.argv[0] = "$name"; from $module import $func; sys.exit($func())' "\$@"
EOF
    chmod +x "$VENV/bin/$name"
done

# The workspace's Python packages on the venv's own path (a .pth file), so that
# `$VENV/bin/python -c "from holonomic_core.model import load_model"` works with
# nothing sourced. The folders are the ones colcon's environment puts on
# PYTHONPATH under build/ (with --symlink-install: build/<pkg>, whose package is
# a symlink to src/) -- the ament_python packages only: tf2_msgs needs its
# libraries on LD_LIBRARY_PATH, and a venv must not take a workspace's message
# package for the system's. Programs that use ROS still need env.sh (the
# wrappers source it).
SITE="$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
(set +u; unset PYTHONPATH; . "$WS/env.sh"; tr ':' '\n' <<<"${PYTHONPATH:-}") | grep "^$WS/build/" \
    > "$SITE/holonomic_workspace.pth.tmp" && mv "$SITE/holonomic_workspace.pth.tmp" "$SITE/holonomic_workspace.pth" \
    || fail "step 4 (writing $SITE/holonomic_workspace.pth)"
log "ready (source ${WS#"$ROOT"/}/env.sh to use the workspace from a shell)"
