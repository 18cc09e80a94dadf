#!/usr/bin/env bash
# One-stop, idempotent set-up: system packages, the Python 3.12 venv, dependencies, and the
# editable build of the C++ core. Quick when everything is already in place.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
VENV="$ROOT/.venv"
say() { echo "[setup] $*"; }

# 1. System packages (Debian): compiler, CMake, Eigen 3.4.
need_apt=()
for pkg in libeigen3-dev cmake g++ make; do
  dpkg -s "$pkg" >/dev/null 2>&1 || need_apt+=("$pkg")
done
if [ ${#need_apt[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  say "installing system packages: ${need_apt[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

# 2. Python 3.12 venv.
if [ ! -x "$VENV/bin/python" ]; then
  PY312=""
  if command -v pyenv >/dev/null 2>&1; then
    PY312=$(ls -d "$(pyenv root)"/versions/3.12*/bin/python3.12 2>/dev/null | sort -V | tail -n 1 || true)
  fi
  [ -z "$PY312" ] && PY312=$(command -v python3.12 || true)
  if [ -z "$PY312" ]; then
    echo "[setup] error: Python 3.12 not found (looked in pyenv and PATH)" >&2; exit 1
  fi
  say "creating .venv with $PY312"
  "$PY312" -m venv "$VENV"
fi
PY="$VENV/bin/python"

# 3. Python dependencies (re-run only when the requirements change).
REQ_STAMP="$VENV/.deps-stamp"
REQ_HASH=$(sha256sum "$ROOT/scripts/requirements.txt" | cut -d' ' -f1)
if [ ! -f "$REQ_STAMP" ] || [ "$(cat "$REQ_STAMP")" != "$REQ_HASH" ]; then
  say "installing Python dependencies"
  "$PY" -m pip install -q --upgrade pip
  "$PY" -m pip install -q -r "$ROOT/scripts/requirements.txt"
  echo "$REQ_HASH" > "$REQ_STAMP"
fi

# 4. Editable build of the C++ core (re-run only when C++/build files change).
# The editable install maps each Python module to its file: the list of modules is part of the
# hash, so a moved or added module re-installs.
SRC_HASH=$( (cat CMakeLists.txt pyproject.toml $(find cpp_dem/include cpp_dem/src cpp_dem/bindings -type f | LC_ALL=C sort);
             find cpp_dem/cpp_dem femcoupling geogrid_dem -name '*.py' | LC_ALL=C sort) | sha256sum | cut -d' ' -f1)
BUILD_STAMP="$VENV/.build-stamp"
if [ ! -f "$BUILD_STAMP" ] || [ "$(cat "$BUILD_STAMP")" != "$SRC_HASH" ] || \
   ! "$PY" -c "import cpp_dem._core as c, geogrid_dem; assert c.GEOGRID" >/dev/null 2>&1; then
  # The default build (with the geogrid): a lean build installed by hand
  # (-DCPP_DEM_GEOGRID=OFF, docs/lean_build.md) is replaced, the CMake cache keeps options.
  say "building the C++ core (editable install)"
  "$PY" -m pip install -q --no-build-isolation --no-deps -e "$ROOT" \
    -Ccmake.define.CPP_DEM_GEOGRID=ON
  echo "$SRC_HASH" > "$BUILD_STAMP"
fi

# 5. The project's own modules byte-compiled (only those changed since: compileall compares
# each file's time stamp). Where PYTHONDONTWRITEBYTECODE is set (as on CI machines), Python
# never writes these itself, and every process (each case run, Dask worker and test process)
# compiled them again: about 0.3 s a process, 100 s of CPU over `make test`.
"$PY" -m compileall -q -j 0 "$ROOT/cpp_dem/cpp_dem" "$ROOT/femcoupling" "$ROOT/geogrid_dem" \
  >/dev/null
touch "$VENV/.bytecode-stamp"  # (when: tests/test_setup_bytecode.py checks what was there then)
say "ready: $($PY -c 'import cpp_dem, sys; print("cpp_dem", "python", sys.version.split()[0], "threads", cpp_dem.get_num_threads())')"
