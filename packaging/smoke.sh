#!/usr/bin/env bash
# Smoke check of the built one-folder app (not part of the test run: build it first with
# `bash packaging/build.sh`). Runs the bundle with an empty environment (no Python, no venv, a
# fresh HOME) on Qt's offscreen platform:
#   1. `panotopo --version`             (start-up time)
#   2. `panotopo demo` at 256x128 px     (writes the recording used below; engine + torch + weights)
#   3. `panotopo gui demo.mp4 --screenshot OUT.png`  (opens the recording, runs, saves the window)
# and checks exit status 0 and a real PNG picture. Prints the timings and the bundle size.
# Usage: bash packaging/smoke.sh [APP_DIR] [OUT.png]   (defaults: dist/panotopo, build/smoke/screenshot.png)
set -euo pipefail
cd "$(dirname "$0")/.."
APP_DIR="${1:-dist/panotopo}"
SHOT="${2:-build/smoke/screenshot.png}"
EXE="$APP_DIR/panotopo"; [ -f "$EXE.exe" ] && EXE="$EXE.exe"  # Windows (Git Bash)
[ -x "$EXE" ] || { echo "smoke: no $EXE; build it with: bash packaging/build.sh" >&2; exit 1; }
mkdir -p "$(dirname "$SHOT")"
SHOT="$(cd "$(dirname "$SHOT")" && pwd)/$(basename "$SHOT")"
rm -f "$SHOT"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
mkdir -p "$WORK/home"

# No Python environment: only the system PATH, a fresh home (no settings, no descriptor cache).
bare() { env -i PATH=/usr/bin:/bin HOME="$WORK/home" LANG=C.UTF-8 QT_QPA_PLATFORM=offscreen "$@"; }
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }
fail() { echo "smoke: FAIL: $*" >&2; exit 1; }

t0=$(now)
version="$(bare "$EXE" --version)" || fail "--version exited $?"
t_version=$(secs "$t0" "$(now)")
[[ "$version" == panotopo\ * ]] || fail "--version printed '$version'"
echo "smoke: $version (--version took ${t_version} s)"

t0=$(now)
bare "$EXE" demo --out "$WORK/demo" --width 256 --input-height 64 -q || fail "demo exited $?"
t_demo=$(secs "$t0" "$(now)")
[ -s "$WORK/demo/demo.mp4" ] && [ -s "$WORK/demo/demo.graphml" ] || fail "demo wrote no demo.mp4/demo.graphml"
echo "smoke: demo recording and map written (${t_demo} s)"

t0=$(now)
bare "$EXE" gui "$WORK/demo/demo.mp4" --screenshot "$SHOT" || fail "gui --screenshot exited $?"
t_shot=$(secs "$t0" "$(now)")
[ -f "$SHOT" ] || fail "no screenshot written"
# A real PNG: the 8-byte signature, an IHDR of a window-sized picture, more than a few KB of pixels.
[ "$(od -An -tx1 -N8 "$SHOT" | tr -d ' \n')" = "89504e470d0a1a0a" ] || fail "$SHOT is not a PNG"
read -r w0 w1 w2 w3 h0 h1 h2 h3 < <(od -An -tu1 -j16 -N8 "$SHOT")
width=$(( (w0 << 24) | (w1 << 16) | (w2 << 8) | w3 )); height=$(( (h0 << 24) | (h1 << 16) | (h2 << 8) | h3 ))
bytes=$(stat -c %s "$SHOT")
(( width >= 800 && height >= 500 )) || fail "screenshot is only ${width}x${height}"
(( bytes > 20000 )) || fail "screenshot is only $bytes bytes"
echo "smoke: screenshot ${width}x${height}, $((bytes / 1024)) KB: $SHOT (gui run took ${t_shot} s)"

echo "smoke: OK  bundle $(du -sh "$APP_DIR" | cut -f1)  --version ${t_version} s  demo ${t_demo} s  screenshot run ${t_shot} s"
