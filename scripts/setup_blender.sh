#!/usr/bin/env bash
# Creates .venv-blender: Blender as a Python module (bpy), in an environment of its own (docs/materials.md#native-materials-and-exports).
# bpy 5.0.1 (the newest for CPython 3.11) needs numpy < 2, jax needs numpy >= 2, and with numpy 2
# bpy's own glTF importer/exporter fail to import, so bpy cannot share .venv. brdffit drives it in
# a worker process run by this interpreter (brdffit/cycles/). Called by `make test` (not by
# `make demo`). Idempotent: does nothing once the stamp exists; VENV_BLENDER=path puts it elsewhere.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
VENV_BLENDER=${VENV_BLENDER:-.venv-blender}
STAMP="$VENV_BLENDER/.installed-bpy-5.0.1"

if [ -e "$STAMP" ]; then
    exit 0
fi
ver=$("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
if [ "$ver" != "3.11" ] && command -v python3.11 >/dev/null 2>&1; then
    PYTHON=python3.11  # bpy 5.0 wheels exist for CPython 3.11 only
    ver=3.11
fi
if [ "$ver" != "3.11" ]; then
    echo "setup-blender: warning: bpy 5.0.1 needs CPython 3.11 ($PYTHON is $ver); Blender tests will be skipped"
    exit 0
fi
if [ ! -x "$VENV_BLENDER/bin/python" ]; then
    "$PYTHON" -m venv "$VENV_BLENDER"
fi
"$VENV_BLENDER/bin/python" -m pip install -q --upgrade pip
# numpy < 2: bpy 5.0's compiled modules and its glTF add-on are built against numpy 1.x
if "$VENV_BLENDER/bin/python" -m pip install -q "bpy==5.0.1" "numpy>=1.24,<2"; then
    "$VENV_BLENDER/bin/python" -c "import bpy" && touch "$STAMP" && echo "setup-blender: $VENV_BLENDER ready"
else
    echo "setup-blender: warning: could not install bpy 5.0.1; Blender tests will be skipped"
fi
