#!/usr/bin/env bash
# Installs the Khronos glTF-Validator (npm package gltf-validator: the reference validator, compiled
# from Dart to JavaScript, no native code) into .node-tools/, for the tests of the glTF exports
# (tests/test_materials_textured.py runs it with node). Called by `make test` (not by `make demo`).
# Idempotent; without node and npm it only warns, and those tests are skipped with a line saying so.
set -euo pipefail
cd "$(dirname "$0")/.."
VERSION=2.0.0-dev.3.10
DEST=.node-tools
if [ -e "$DEST/node_modules/gltf-validator/package.json" ] \
   && grep -q "\"version\": \"$VERSION\"" "$DEST/node_modules/gltf-validator/package.json"; then
    exit 0
fi
if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    echo "setup-gltf-validator: warning: no node/npm; the glTF validation tests will be skipped"
    exit 0
fi
mkdir -p "$DEST"
if npm install --prefix "$DEST" --no-audit --no-fund --no-save --silent "gltf-validator@$VERSION"; then
    echo "setup-gltf-validator: $DEST ready"
else
    echo "setup-gltf-validator: warning: could not install gltf-validator; the glTF validation tests will be skipped"
fi
