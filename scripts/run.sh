#!/usr/bin/env bash
# The main job: install what is missing, build, and run bounce on the default scene (the
# published Cornell box, millimetres): per-bounce EXR, PNG previews, contact sheet, baked PLY,
# and the viewer page (the glTF bake with every term, in a browser).
# Outputs go to out/ (override: OUT=dir scripts/run.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j "$(nproc)"
OUT=${OUT:-out}
mkdir -p "$OUT"
SCENE=meshes/cornell-box.obj
# Form factors through the cache (keyed by scene, meshing and options): the bake and the viewer share
# one assembly (1200 patches); the images use the final gather's coarser default mesh (300 patches).
COMMON=(--unit mm --cache "$OUT/cornell-box.F")
IMAGES=(--unit mm --cache "$OUT/cornell-box-images.F")
./build/bounce info "$SCENE" --unit mm -q | sed -n '1,9p'
./build/bounce bounces "$SCENE" "${IMAGES[@]}" -n 4 -o "$OUT/cornell-box.exr"
./build/bounce bake "$SCENE" "${COMMON[@]}" -o "$OUT/cornell-box.ply"
./build/bounce view "$SCENE" "${COMMON[@]}" -o "$OUT/cornell-box.html"
echo
echo "bounce: outputs in $OUT/:"
echo "  cornell-box.exr         layers E, KE, K2E, K3E, K4E, rest, L (radiance, W m^-2 sr^-1)"
echo "  cornell-box.<layer>.png sRGB previews; cornell-box.sheet.png: all layers side by side"
echo "  cornell-box.ply         baked per-vertex radiance (float colours)"
echo "  cornell-box.html        the viewer: open it in a browser, show each bounce alone or summed"
echo "  cornell-box.bake.glb    the viewer's bake (glTF, every term): bounce view it again without solving"
