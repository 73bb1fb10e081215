#!/usr/bin/env bash
# The Python client's tests (ctest: Python.ClientAgainstALiveServer): installs
# clients/python with pip into a fresh virtual environment (Debian's python3, its flatbuffers
# and numpy packages seen through --system-site-packages; nothing downloaded), then runs
# tests/python/test_client.py against a penumbra-server process.
#   $1  the build folder (penumbra-server is there; the environment goes there too)
set -euo pipefail
build=$(cd "$1" && pwd)
source_dir=$(cd "$(dirname "$0")/../.." && pwd)
python=${PENUMBRA_PYTHON:-/usr/bin/python3}
venv="$build/python-venv"
rm -rf "$venv"
"$python" -m venv --system-site-packages "$venv"
# Built from a copy, so that the source tree gets no build/ or .egg-info folders.
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp -r "$source_dir/clients/python" "$work/python"
PENUMBRA_FBS="$source_dir/protocol/penumbra.fbs" "$venv/bin/pip" install --quiet \
    --no-build-isolation --no-deps --no-index "$work/python"
cd "$work"  # not the source folder: the installed package is the one imported
PENUMBRA_BUILD="$build" PENUMBRA_SCENES="$source_dir/scenes" \
    "$venv/bin/python" "$source_dir/tests/python/test_client.py" 2>&1
