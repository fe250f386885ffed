#!/usr/bin/env bash
# glTF bakes through the Khronos validator (tests/gltf_validate.js): the Cornell box (.glb with
# every term, .gltf + .bin on the input mesh with the display set), the same from Blender's glTF export and McGuire's Cornell box as
# published (skipped visibly when ../shared is missing). The bunny box's 69,460 polygons are
# validated by bench/run.sh --big (a big scene: a minute and a half of baking).
# usage: gltf_validate.sh BOUNCE SOURCE_DIR OUT_DIR
set -euo pipefail
bounce=$1 src=$2 out=$3
mkdir -p "$out"
export NODE_PATH="$src/web/node_modules"
if ! command -v node >/dev/null 2>&1; then
  echo "SKIP: no node (scripts/setup.sh installs Node.js and the validator)"
  exit 77
fi
files=()
# shadow rays: these bakes test the glTF, not the visible parts (tests/test_ff_visibility.c), which
# would triple their form factors' time (and more under the sanitizers)
vis=(--ff-visibility rays)
"$bounce" bake "$src/meshes/cornell-box.obj" --unit mm -q --patches 400 --per-bounce "${vis[@]}" -o "$out/cornell.glb" 2>/dev/null
"$bounce" bake "$src/meshes/cornell-box.obj" --unit mm -q --patches 400 --mesh input --ldr --gather none "${vis[@]}" -o "$out/cornell-input.gltf" 2>/dev/null
# (the input-mesh bakes take the patches' values, --gather none: the file's layout is what is checked; the
# gathered, refined mesh is the .glb bakes')
# from a glTF input: Blender's export of the box (every material doubleSided: each side baked), refined up to
# 1,200 vertices (the file's layout is what is checked; 4.7 s, 3,000 took 10 s; the defaults refine the
# double-sided box to 9,400 in a half-minute: its 300 large patches send most gather rays through the near
# hits' own gathers)
"$bounce" bake "$src/meshes/cornell-box-blender.glb" -q --patches 300 --per-bounce --bake-vertices 1200 "${vis[@]}" -o "$out/blender.glb" 2>/dev/null
"$bounce" bake "$src/meshes/cornell-box-blender.glb" -q --patches 300 --mesh input --gather none "${vis[@]}" -o "$out/blender-input.gltf" 2>/dev/null
files+=("$out/cornell.glb" "$out/cornell-input.gltf" "$out/blender.glb" "$out/blender-input.gltf")
mcguire="$src/../shared/data/external/mcguire-cornell/CornellBox-Original.obj"
if [ -f "$mcguire" ]; then
  # the patches as they are: a real file's glTF is checked here; the refined mesh by the two bakes above
  "$bounce" bake "$mcguire" -q --per-bounce --bake-vertices 0 "${vis[@]}" -o "$out/mcguire.glb" 2>/dev/null
  files+=("$out/mcguire.glb")
else
  echo "SKIPPED PART: $mcguire is missing (../shared): McGuire's box not baked"
fi
exec node "$src/tests/gltf_validate.js" "${files[@]}"
