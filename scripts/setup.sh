#!/usr/bin/env bash
# Installs bounce's build and test dependencies from Debian 12 packages when any is missing.
# Idempotent: does nothing (and needs no network) when everything is present.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  libopenmesh-dev            # mesh structure, PLY/OFF input, baked output
  libopenexr-dev             # OpenEXRCore: multi-layer EXR (C API)
  libopenimageio-dev openimageio-tools   # PNG previews, contact sheet, image comparison
  libembree-dev              # all ray casting
  libopenmpi-dev openmpi-bin # bounce under mpirun -np P (include/bounce/dist.h)
  liblapacke-dev libopenblas-dev         # the dense direct solve (reference answer)
  libtinyobjloader-dev       # an independent OBJ reader the tests compare ours with
  libtinygltf-dev            # glTF 2.0 input (.gltf, .glb)
  assimp-testmodels          # tests: real glTF 2.0 files, broken ones among them (/usr/share/assimp/models/glTF2)
  libplplot-dev plplot-driver-cairo      # study plots (PNG, SVG)
  fonts-dejavu-core          # labels on the contact sheet
  clang libclang-rt-14-dev   # libFuzzer harnesses; clang also builds the live page's WebAssembly kernel
  lld                        # wasm-ld: links that kernel (web/live-kernel.c)
  chromium                   # headless browser: tests open the study report page
  python3                    # tests: the glTF bake read back by a reader of its own
  python3-numpy python3-pytest   # the Python package (python/bounce) and its tests
  python3-venv python3-setuptools python3-wheel   # pip install of the package into a venv (pyproject.toml)
  mypy                       # the package's type hints checked (python.mypy)
  python3-scipy              # the package's sparse F and K as a scipy LinearOperator (and their tests)
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
# Node.js and npm (the npm registry's packages in web/: three.js, meshoptimizer, the Khronos glTF validator): Debian's
# nodejs and npm unless a node with npm is already there (a NodeSource nodejs carries its own npm,
# and Debian's npm package would conflict with it).
if ! command -v npm >/dev/null 2>&1; then
  missing+=(nodejs npm)
fi
web_deps() {
  if [ ! -d web/node_modules/gltf-validator ] || [ ! -d web/node_modules/three ] ||
     [ ! -d web/node_modules/meshoptimizer ]; then
    echo "setup: npm ci in web/ (three.js, meshoptimizer, gltf-validator)" >&2
    (cd web && npm ci --no-audit --no-fund --loglevel=error)
  fi
}
cd "$(dirname "$0")/.."
if [ ${#missing[@]} -eq 0 ]; then
  web_deps
  exit 0
fi
echo "setup: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "setup: need root (or sudo) to apt-get install: ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
web_deps
