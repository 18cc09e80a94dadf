#!/usr/bin/env bash
# Builds bench/profile_step.cpp against the core's sources (not the installed module) into
# build/profile/profile_step, with the Release flags of the module (-O3 -DNDEBUG -fno-math-errno -ffp-contract=off: without the last, GCC fuses multiply-adds differently in the threaded and the serial code, and the checksums of two thread counts differ). Extra compiler flags in CXXFLAGS_EXTRA (e.g. -march=x86-64-v3).
# INCREMENTAL=1: one object file a source, kept under build/profile/obj/<hash of the flags>
# with its header dependencies (-MMD), compiled by make -j (JOBS, default: every core); after a
# change to one source only that source is compiled again (about 40 s instead of 3 min).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="${OUT:-$ROOT/build/profile/profile_step}"
mkdir -p "$(dirname "$OUT")"
# CLONES=0: without the x86-64-v4/v3 variants of the hot loops (CMake's CPP_DEM_CLONES=OFF).
CLONE_DEF="-DCPP_DEM_CLONES"
[ "${CLONES:-1}" = "0" ] && CLONE_DEF=""
FLAGS="-std=c++17 -O3 -DNDEBUG -g -ffp-contract=off -fno-math-errno -fopenmp -DEIGEN_DONT_PARALLELIZE $CLONE_DEF ${CXXFLAGS_EXTRA:-} -I$ROOT/cpp_dem/include -I/usr/include/eigen3"
SOURCES="$ROOT/bench/profile_step.cpp $(find "$ROOT"/cpp_dem/src -name "*.cpp" ! -name off.cpp | sort)"
if [ "${INCREMENTAL:-0}" = "1" ]; then
  OBJ="$ROOT/build/profile/obj/$(echo "$FLAGS" | sha1sum | cut -c1-12)"
  mkdir -p "$OBJ"
  OBJS=""
  RULES=""
  for s in $SOURCES; do
    o="$OBJ/$(echo "${s#$ROOT/}" | tr / _).o"
    OBJS="$OBJS $o"
    RULES="$RULES$o: $s
	g++ $FLAGS -MMD -MP -c $s -o $o
-include ${o%.o}.d
"
  done
  printf '%s: %s\n\tg++ %s %s -o %s\n%s' "$OUT" "$OBJS" "$FLAGS" "$OBJS" "$OUT" "$RULES" \
    > "$OBJ/Makefile"
  make --no-print-directory -j "${JOBS:-$(nproc)}" -f "$OBJ/Makefile" "$OUT" >&2
else
  g++ $FLAGS $SOURCES -o "$OUT"
fi
echo "$OUT"
