#!/usr/bin/env bash
# One command from a fresh clone to a result, doing its own set-up:
#   scripts/quickstart.sh render [clrt render options]   render (default: the built-in scene)
#   scripts/quickstart.sh test [pytest options]          run the test suite
# Set-up: a virtual environment in .venv (CLRT_VENV to move it) with clrt
# installed in editable mode, and -- only when no OpenCL device is found --
# Debian's CPU driver, pocl-opencl-icd (PyPI's pocl-binary-distribution does
# not work on these machines: "unknown target CPU 'generic'").
# Paths given to `render` (the mesh, -o) are relative to the directory the
# script is run from, as for clrt itself; set-up and `test` run in the repository.
set -euo pipefail
caller=$PWD
repo=$(cd "$(dirname "$0")/.." && pwd)
cd "$repo"

usage() { echo "usage: $0 render [clrt render options] | test [pytest options]" >&2; exit 2; }
[ $# -ge 1 ] || usage
command=$1; shift
case "$command" in render|test) ;; *) usage ;; esac

venv=${CLRT_VENV:-.venv}
case "$venv" in   # a CLRT_VENV given by the caller is relative to the caller's directory
    /*) ;;
    *) if [ -n "${CLRT_VENV:-}" ]; then venv="$caller/$venv"; else venv="$repo/$venv"; fi ;;
esac
if [ ! -x "$venv/bin/python" ]; then
    echo "quickstart: creating virtual environment $venv" >&2
    python3 -m venv "$venv"
fi
stamp="$venv/.clrt-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "quickstart: installing clrt and its dependencies into $venv" >&2
    "$venv/bin/python" -m pip install -q --disable-pip-version-check -e ".[test]"
    touch "$stamp"
fi

has_opencl_device() {
    "$venv/bin/python" - <<'PY' 2>/dev/null
import sys, pyopencl as cl
sys.exit(0 if any(p.get_devices() for p in cl.get_platforms()) else 1)
PY
}
if ! has_opencl_device; then
    echo "quickstart: no OpenCL device found; installing Debian's pocl-opencl-icd (CPU OpenCL)" >&2
    sudo=""
    [ "$(id -u)" = 0 ] || sudo=sudo
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq pocl-opencl-icd >/dev/null
    has_opencl_device || { echo "quickstart: still no OpenCL device; see 'clrt info'" >&2; exit 3; }
fi

case "$command" in
    render) cd "$caller" && exec "$venv/bin/clrt" render "$@" ;;
    test) exec "$venv/bin/python" -m pytest "$@" ;;
esac
