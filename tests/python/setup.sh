#!/usr/bin/env bash
# Creates the Python environment the interop tests use (pymavlink and MAVProxy from PyPI) in target/pyenv.
# Safe to run again: it does nothing when the environment is complete.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
venv="${GCS_PYENV:-$root/target/pyenv}"
if [ -x "$venv/bin/python" ] && "$venv/bin/python" -c "import pymavlink, MAVProxy" 2>/dev/null; then
  exit 0
fi
python3 -m venv "$venv"
"$venv/bin/pip" install --quiet --disable-pip-version-check -r "$here/requirements.txt"
"$venv/bin/python" -c "import pymavlink, MAVProxy"
echo "pymavlink and MAVProxy ready in $venv" >&2
