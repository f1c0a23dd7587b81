#!/usr/bin/env bash
# Screenshots of the real app in a real X11 window (Xvfb), at laptop and desktop sizes.
#
#   packaging/xvfb_screenshots.sh [OUT_DIR] [SIZES...]
#
# OUT_DIR defaults to docs/screenshots; SIZES default to "1280x720 1920x1080". For each
# size it starts an Xvfb screen of that size, runs `python -m gui.screenshots` on the xcb
# platform (the demo recording, the engine, a little curation) and saves every view into
# OUT_DIR/<size>/, plus screen.png (the X screen itself, via ImageMagick's `import`).
# Needs: Xvfb, ImageMagick (`import`), the Qt xcb libraries (see the README,
# "System libraries on Linux"). Debian/Ubuntu: apt-get install -y xvfb imagemagick
set -euo pipefail
out=${1:-docs/screenshots}
shift || true
sizes=("$@")
[ ${#sizes[@]} -gt 0 ] || sizes=(1280x720 1920x1080)
for tool in Xvfb import; do
    command -v "$tool" >/dev/null || { echo "xvfb_screenshots: $tool is not installed" >&2; exit 1; }
done
display=:${XVFB_DISPLAY:-97}
for size in "${sizes[@]}"; do
    Xvfb "$display" -screen 0 "${size}x24" -nolisten tcp >/dev/null 2>&1 &
    xvfb_pid=$!
    trap 'kill $xvfb_pid 2>/dev/null || true' EXIT
    for _ in $(seq 50); do [ -e "/tmp/.X11-unix/X${display#:}" ] && break; sleep 0.1; done
    DISPLAY=$display QT_QPA_PLATFORM=xcb PANOTOPO_SHOT_ROOT=1 \
        python -m gui.screenshots "$out/$size" "$size"
    kill "$xvfb_pid"; wait "$xvfb_pid" 2>/dev/null || true
    trap - EXIT
done
