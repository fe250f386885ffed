#!/usr/bin/env bash
# The Python package's tests against the package as a user installs it: a venv made with
# --system-site-packages (Debian's numpy and pytest), `pip install --no-build-isolation --no-index` of a
# copy of the sources (pyproject.toml, python/: the checkout is left as it was), the library put into
# the venv's prefix by `cmake --install`; then pytest with neither PYTHONPATH nor BOUNCE_LIBRARY, so the
# package and the library are found as a user's would be. Skipped (77) where numpy, pytest or venv
# are missing (scripts/setup.sh installs them).
# usage: run.sh LIBBOUNCE BOUNCE_EXE SOURCE_DIR CMAKE
set -euo pipefail
py=/usr/bin/python3
[ -x "$py" ] || py=python3
if ! "$py" -c "import numpy, pytest, venv, ensurepip" 2>/dev/null; then
  echo "SKIP: numpy, pytest and venv are not all importable by $py (scripts/setup.sh installs python3-numpy, python3-pytest, python3-venv)"
  exit 77
fi
lib=$1 exe=$2 src=$3 cmake=${4:-cmake}
build=$(dirname "$lib")
work="$build/python-install"
rm -rf "$work"
mkdir -p "$work/src/doc"
cp -r "$src/pyproject.toml" "$src/python" "$work/src/"
cp "$src/doc/python.md" "$work/src/doc/"
"$py" -m venv --system-site-packages "$work/venv"
"$work/venv/bin/pip" install -q --no-build-isolation --no-index "$work/src"
"$cmake" --install "$build" --prefix "$work/venv" >/dev/null
unset BOUNCE_LIBRARY PYTHONPATH
export BOUNCE_EXE=$exe BOUNCE_SOURCE_DIR=$src BOUNCE_INSTALLED_IN="$work/venv"
cd "$work"
exec "$work/venv/bin/python" -m pytest -q --durations=12 -p no:cacheprovider "$src/tests/python"
