#!/usr/bin/env bash
# The main job: install what is missing, build, and run bounce on the default scene
# (the published Cornell box). Outputs go to out/ (override: OUT=dir scripts/run.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j "$(nproc)"
OUT=${OUT:-out}
mkdir -p "$OUT"
SCENE=meshes/cornell-box.obj
set -x
./build/bounce info "$SCENE" --unit mm
