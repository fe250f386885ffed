#!/usr/bin/env bash
# The Python package's tests under Debian's python3 (numpy and pytest from python3-numpy and
# python3-pytest, which scripts/setup.sh installs); skipped (77) where they are missing.
# usage: run.sh LIBBOUNCE BOUNCE_EXE SOURCE_DIR
set -euo pipefail
py=/usr/bin/python3
[ -x "$py" ] || py=python3
if ! "$py" -c "import numpy, pytest" 2>/dev/null; then
  echo "SKIP: numpy and pytest are not importable by $py (scripts/setup.sh installs python3-numpy, python3-pytest)"
  exit 77
fi
export BOUNCE_LIBRARY=$1 BOUNCE_EXE=$2 BOUNCE_SOURCE_DIR=$3 PYTHONPATH="$3/python${PYTHONPATH:+:$PYTHONPATH}"
exec "$py" -m pytest -q -p no:cacheprovider "$3/tests/python"
