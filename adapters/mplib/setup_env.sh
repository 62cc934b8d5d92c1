#!/usr/bin/env bash
# Create the mplib adapter's own virtualenv and install mplib 0.2.1 with numpy 1.x into it.
#
#   bash adapters/mplib/setup_env.sh [VENV_DIR]        # default VENV_DIR: .venv-mplib at the repository root
#   PYTHON=python3.10 bash adapters/mplib/setup_env.sh # choose the interpreter
#
# mplib 0.2.1 requires numpy<2 (with numpy 2 it crashes building a Pose) and ships wheels for
# CPython 3.8 to 3.12 (manylinux x86_64) only, so it cannot live in the suite's environment
# (numpy 2). The script prints the line to export for the adapter's test, MPLIB_PYTHON=...
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="${1:-$root/.venv-mplib}"
python="${PYTHON:-}"
if [ -z "$python" ]; then
    for candidate in python3.12 python3.11 python3.10 python3.9 python3.8; do
        # (a pyenv shim may exist for a version that is not installed: run it to be sure)
        if "$candidate" -c pass >/dev/null 2>&1; then python="$candidate"; break; fi
    done
fi
if [ -z "$python" ]; then
    echo "error: mplib 0.2.1 has wheels for CPython 3.8-3.12 only; none found (set PYTHON=...)" >&2
    exit 2
fi
"$python" -c 'import sys; v = sys.version_info[:2]; sys.exit(0 if (3, 8) <= v <= (3, 12) else
    f"error: {sys.executable} is Python {v[0]}.{v[1]}; mplib 0.2.1 has wheels for 3.8-3.12 only")'
"$python" -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet -r "$here/requirements.txt"
"$venv/bin/python" -c 'import mplib, numpy; print(f"mplib {mplib.__version__}, numpy {numpy.__version__}")'
echo "MPLIB_PYTHON=$venv/bin/python"
