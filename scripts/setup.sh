#!/usr/bin/env bash
# Creates the project-local virtual environment .venv and installs brdffit with its test extras.
# Mitsuba's LLVM back end needs libLLVM >= 16 (with 14/15 alone it aborts the process), so on
# Debian/Ubuntu, as root, this also installs libllvm19 when no libLLVM >= 16 is present.
# Without one, brdffit still runs: it falls back to a scalar Mitsuba variant with a warning.
# The explorer's browser test (tests/test_explore_browser.py) drives Debian's chromium: installed
# the same way (root and apt-get) when /usr/bin/chromium is missing; elsewhere that test is skipped.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}

have_llvm16() {
    local f v
    for f in /usr/lib/x86_64-linux-gnu/libLLVM*.so* /usr/lib/aarch64-linux-gnu/libLLVM*.so* \
             /usr/lib/llvm-*/lib/libLLVM*.so* /usr/local/lib/libLLVM*.so*; do
        [ -e "$f" ] || continue
        v=$(basename "$f" | sed -E 's/^libLLVM-?([0-9]+).*/\1/')
        [[ "$v" =~ ^[0-9]+$ ]] && [ "$v" -ge 16 ] && return 0
    done
    return 1
}

if ! have_llvm16; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing libllvm19 for Mitsuba's LLVM back end"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y -q libllvm19 >/dev/null 2>&1 \
            || { apt-get update -q >/dev/null 2>&1 && apt-get install -y -q libllvm19 >/dev/null 2>&1; } \
            || echo "setup: warning: could not install libllvm19; brdffit will render with the slower scalar Mitsuba variant"
    else
        echo "setup: warning: no libLLVM >= 16 found and cannot install one (need root + apt);" \
             "brdffit will render with the slower scalar Mitsuba variant"
    fi
fi

if [ ! -x /usr/bin/chromium ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing chromium for the explorer's browser test"
        export DEBIAN_FRONTEND=noninteractive
        apt-get install -y -q chromium >/dev/null 2>&1 \
            || { apt-get update -q >/dev/null 2>&1 && apt-get install -y -q chromium >/dev/null 2>&1; } \
            || echo "setup: warning: could not install chromium; the explorer's browser test will fail"
    else
        echo "setup: warning: no /usr/bin/chromium and cannot install it (need root + apt);" \
             "the explorer's browser test is skipped"
    fi
fi

if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
fi
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test]"
echo "setup: .venv ready"
