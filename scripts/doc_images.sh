#!/usr/bin/env bash
# The pictures in doc/images/ that show the viewer, made again from the commands the docs give:
# `bounce view` on the Cornell box with the defaults, then headless Chromium (software WebGL) at
# 900 x 560: L with the panel open, and K2E alone with its own exposure (#terms=K2E&ev=auto).
# usage: scripts/doc_images.sh [BOUNCE]   (default build/bounce; writes doc/images/viewer-cornell-*.png)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bounce=${1:-$root/build/bounce}
browser=$(command -v chromium || command -v chromium-browser || true)
[ -n "$browser" ] || { echo "doc_images.sh: no chromium (scripts/setup.sh installs it)" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bounce" view "$root/meshes/cornell-box.obj" --unit mm -q -o "$work/cornell.html"
shot() {   # shot NAME FRAGMENT
    "$browser" --headless --no-sandbox --use-gl=swiftshader --enable-unsafe-swiftshader --virtual-time-budget=8000 \
        --window-size=900,560 --hide-scrollbars --screenshot="$work/$1.png" "file://$work/cornell.html#$2" 2>/dev/null
    mv "$work/$1.png" "$root/doc/images/viewer-cornell-$1.png"
    echo "wrote doc/images/viewer-cornell-$1.png"
}
shot L ""
shot K2E "terms=K2E&ev=auto&panel=folded"
