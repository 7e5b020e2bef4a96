#!/usr/bin/env bash
# Take docs/addon_panel.png, a real screenshot of the add-on's sidebar panel in Blender.
#
# bpy from PyPI (what scripts/test_addon.sh uses) always runs in background mode and draws
# no UI, so this runs a windowed Blender 4.3 (Debian trixie's `blender` package, the
# first Debian Blender with the 4.2 extension system) under Xvfb with Mesa's software
# OpenGL, in a trixie chroot built with debootstrap from Debian's archive. Needs root
# (debootstrap, mount, chroot) and about 2 GB of disk; the first run takes a while.
#
# Usage: sudo bash scripts/screenshot_addon.sh [OUT.png]    (default docs/addon_panel.png)
#        ROOTFS=/path/to/chroot to choose where the chroot lives (kept for the next run).
set -euo pipefail
OUT=$(realpath -m "${1:-$(dirname "$0")/../docs/addon_panel.png}")
cd "$(dirname "$0")/.."
REPO=$(pwd)
ROOTFS=${ROOTFS:-/tmp/cloth_usd_trixie}
MIRROR=${MIRROR:-http://deb.debian.org/debian}
SITE=/opt/cloth_usd_site  # usd-core for Blender's Python (Debian's 3.13)

if [ ! -x "$ROOTFS/usr/bin/apt-get" ]; then
    command -v debootstrap >/dev/null || apt-get install -y debootstrap
    debootstrap --variant=minbase trixie "$ROOTFS" "$MIRROR"
fi

mounted=()
cleanup() { for ((i=${#mounted[@]}-1; i>=0; i--)); do umount "${mounted[$i]}" || umount -l "${mounted[$i]}" || true; done; }
trap cleanup EXIT
for d in proc sys dev dev/pts; do
    if ! mountpoint -q "$ROOTFS/$d"; then mount --bind "/$d" "$ROOTFS/$d"; mounted+=("$ROOTFS/$d"); fi
done
mkdir -p "$ROOTFS/repo"
mount --bind "$REPO" "$ROOTFS/repo"; mounted+=("$ROOTFS/repo")
cp /etc/resolv.conf "$ROOTFS/etc/resolv.conf"

in_root() { chroot "$ROOTFS" env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8 "$@"; }

if [ ! -x "$ROOTFS/usr/bin/blender" ]; then
    in_root bash -c 'apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
        --no-install-recommends blender xvfb libgl1-mesa-dri x11-apps xdotool netpbm python3-pip \
        python3-numpy python3-scipy python3-tqdm python3-threadpoolctl'
fi
# cloth_usd's runtime dependency that Debian lacks (usd-core: pxr) for Blender's Python;
# numpy, scipy, tqdm and threadpoolctl come from Debian above, cloth_usd from this checkout (/repo).
# The wheel is fetched by this machine's pip (its index and certificates), installed by
# the chroot's.
if [ ! -d "$ROOTFS$SITE/pxr" ]; then
    rm -rf "$ROOTFS/tmp/wheels"
    python3 -m pip download -q --only-binary=:all: --no-deps --python-version 3.13 \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
        -d "$ROOTFS/tmp/wheels" "usd-core>=24.0"
    in_root bash -c "python3 -m pip install -q --break-system-packages --no-index --no-deps \
        --target $SITE /tmp/wheels/usd_core-*.whl"
fi

# Blender under Xvfb: preferences without the splash (a first start shows Quick Setup over
# the view), then the add-on loaded, baked and shown by screenshot_addon.py, which says
# READY with the 3D view's rectangle. Then, as a person would: drag the sidebar's edge
# wider so the inspected lines fit, and take X's own screenshot of the 3D view (xwd;
# Blender's screenshot operators read back black under Xvfb's software GL).
rm -f "$ROOTFS/tmp/addon_panel.png"
in_root env CLOTH_USD_SITE="$SITE" bash -euo pipefail -c '
export HOME=/tmp/blender_home LIBGL_ALWAYS_SOFTWARE=1 DISPLAY=:77
sync=/tmp/shot_sync
rm -rf "$HOME" "$sync" /tmp/shots; mkdir -p "$HOME" "$sync"
blender -b --python-expr "import bpy; bpy.context.preferences.view.show_splash = False; \
bpy.ops.wm.save_userpref()" >/dev/null
Xvfb :77 -screen 0 1500x900x24 -nolisten tcp >/dev/null 2>&1 & xvfb=$!
blender -P /repo/scripts/screenshot_addon.py -- "$sync" & blender=$!
trap "touch $sync/DONE; sleep 2; kill $blender $xvfb 2>/dev/null || true" EXIT
for _ in $(seq 600); do [ -f "$sync/READY" ] && break; kill -0 $blender || exit 1; sleep 0.5; done
read -r x y w h sb < <(python3 -c "import json; r = json.load(open(\"$sync/READY\")); \
print(r[\"x\"], r[\"y\"], r[\"width\"], r[\"height\"], r[\"sidebar\"])")
# The sidebar overlaps the view: its edge can be dragged beside the panel (near its top),
# a few pixels inside the region; try offsets until the width grows.
edge=$((x + w - sb)); py=$((y + 150))
for off in 9 7 11 5 13 3 15; do
    xdotool mousemove $((edge + off)) $py; sleep 0.5; xdotool mousemove $((edge + off + 1)) $py
    sleep 0.5; xdotool mousedown 1
    for dx in 40 80 120 160 200; do sleep 0.2; xdotool mousemove $((edge + off + 1 - dx)) $py; done
    sleep 0.3; xdotool mouseup 1; sleep 1.5
    [ "$(cat $sync/WIDTH)" -gt $((sb + 100)) ] && break
done
echo "sidebar width: $sb -> $(cat $sync/WIDTH) px"
xdotool mousemove $((x + 40)) $((y + h - 40)); sleep 4
xwd -root -silent | xwdtopnm 2>/dev/null | pnmcut -left $x -top $y -width $w -height $h \
    | pnmtopng > /tmp/addon_panel.png
'
mkdir -p "$(dirname "$OUT")"
cp "$ROOTFS/tmp/addon_panel.png" "$OUT"
ls -l "$OUT"
