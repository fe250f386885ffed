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
  liblapacke-dev libopenblas-dev         # the dense direct solve (reference answer)
  libtinyobjloader-dev       # an independent OBJ reader the tests compare ours with
  libplplot-dev plplot-driver-cairo      # study plots (PNG, SVG)
  fonts-dejavu-core          # labels on the contact sheet
  clang libclang-rt-14-dev   # libFuzzer harnesses
  chromium                   # headless browser: tests open the study report page
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -eq 0 ]; then
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
