#!/usr/bin/env bash
# Build the one-folder desktop app into dist/panotopo/ (Linux; see packaging/README.md for others).
# Uses the current Python environment: panotopo's dependencies must already be installed there
# (python3 -m pip install torch==2.13.0 -e .). PyInstaller is installed if missing.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-python3}"
if ! "$PY" -c "import PyInstaller" 2>/dev/null; then
    "$PY" -m pip install "pyinstaller>=6"
fi
"$PY" -m PyInstaller packaging/panotopo.spec --noconfirm --distpath dist --workpath build/pyinstaller "$@"
echo "built dist/panotopo/panotopo ($(du -sh dist/panotopo | cut -f1))"
