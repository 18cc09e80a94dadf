#!/usr/bin/env bash
# Builds bench/profile_step.cpp against the core's sources (not the installed module) into
# build/profile/profile_step, with the Release flags of the module (-O3 -DNDEBUG -fno-math-errno -ffp-contract=off: without the last, GCC fuses multiply-adds differently in the threaded and the serial code, and the checksums of two thread counts differ). Extra compiler flags in CXXFLAGS_EXTRA (e.g. -march=x86-64-v3).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
OUT="${OUT:-$ROOT/build/profile/profile_step}"
mkdir -p "$(dirname "$OUT")"
# CLONES=0: without the x86-64-v4/v3 variants of the hot loops (CMake's CPP_DEM_CLONES=OFF).
CLONE_DEF="-DCPP_DEM_CLONES"
[ "${CLONES:-1}" = "0" ] && CLONE_DEF=""
g++ -std=c++17 -O3 -DNDEBUG -g -ffp-contract=off -fno-math-errno -fopenmp -DEIGEN_DONT_PARALLELIZE $CLONE_DEF ${CXXFLAGS_EXTRA:-} \
  -I"$ROOT/cpp_dem/include" -I/usr/include/eigen3 \
  "$ROOT/bench/profile_step.cpp" $(find "$ROOT"/cpp_dem/src -name "*.cpp" ! -name off.cpp | sort) -o "$OUT"
echo "$OUT"
