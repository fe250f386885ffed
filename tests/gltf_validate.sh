#!/usr/bin/env bash
# glTF bakes through the Khronos validator (tests/gltf_validate.js): the Cornell box (.glb with
# every term, .gltf + .bin on the input mesh with the display set), McGuire's Cornell box as
# published, and the bunny in the Cornell box (69,460 polygons; not in the sanitized build, where
# it would take minutes). The shared scenes skip visibly when ../shared is missing.
# usage: gltf_validate.sh BOUNCE SOURCE_DIR OUT_DIR SANITIZED(0|1)
set -euo pipefail
bounce=$1 src=$2 out=$3 sanitized=$4
mkdir -p "$out"
export NODE_PATH="$src/web/node_modules"
if ! command -v node >/dev/null 2>&1; then
  echo "SKIP: no node (scripts/setup.sh installs Node.js and the validator)"
  exit 77
fi
files=()
"$bounce" bake "$src/meshes/cornell-box.obj" --unit mm -q --per-bounce -o "$out/cornell.glb" 2>/dev/null
"$bounce" bake "$src/meshes/cornell-box.obj" --unit mm -q --mesh input --ldr -o "$out/cornell-input.gltf" 2>/dev/null
files+=("$out/cornell.glb" "$out/cornell-input.gltf")
mcguire="$src/../shared/data/external/mcguire-cornell/CornellBox-Original.obj"
if [ -f "$mcguire" ]; then
  "$bounce" bake "$mcguire" -q --per-bounce -o "$out/mcguire.glb" 2>/dev/null
  files+=("$out/mcguire.glb")
else
  echo "SKIPPED PART: $mcguire is missing (../shared): McGuire's box not baked"
fi
bunny="$src/../shared/data/scenes/bunny-box.obj"
if [ "$sanitized" = 1 ]; then
  echo "SKIPPED PART: the bunny box is baked in the normal build only"
elif [ -f "$bunny" ]; then
  # eps 1e-2: the container and its 69k polygons are what is checked here, not the solution
  "$bounce" bake "$bunny" --unit mm -q --eps 1e-2 --per-bounce --mesh input -o "$out/bunny-box.glb" 2>/dev/null
  files+=("$out/bunny-box.glb")
else
  echo "SKIPPED PART: $bunny is missing (../shared): the bunny box not baked"
fi
exec node "$src/tests/gltf_validate.js" "${files[@]}"
