#!/usr/bin/env bash
# Regenerates the pictures of the README (run from the repository root).
set -euo pipefail
cargo build --release -q
bin=target/release/rigidcells
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
$bin demo --out "$work" -q
$bin deform "$work/bar.ply" -o "$work/bar_out.ply" --edit "$work/bend.toml" --cell-size 0.25 \
    --preview docs/bar_preview.png --strain --size 300x220 -q
cp "$work/gingerbread.png" docs/gingerbread.png
cp "$work/gingerbread_bent.png" docs/gingerbread_bent.png
$bin render ../shared/data/meshes/dragon_11k_binary.ply -o docs/dragon.png --size 360x300 --up z
$bin render ../shared/data/las/autzen_trim.las -o docs/autzen.png --azimuth -90 --elevation 90 --size 360x300
# The editor in Chromium (Debian's chromium and chromedriver): after a drag, and with its help open.
RIGIDCELLS_BIN=$bin python3 tests/browser/editor_test.py --screenshot docs/editor.png \
    --help-screenshot docs/editor_help.png
# Blender's window under a virtual display (Debian's blender and xvfb), with the wheel
# unpacked in target/blender-site: the panel, and Follow at three frames of an animation.
if command -v blender >/dev/null && [ -d target/blender-site ]; then
    blender -b --factory-startup --python-expr \
        "import bpy; bpy.ops.wm.save_as_mainfile(filepath='$work/start.blend')"
    for shot in panel follow; do
        xvfb-run -a -s "-screen 0 1500x900x24" blender "$work/start.blend" --enable-event-simulate \
            --python "tools/python/blender_$shot.py" -- "docs/blender_$shot.png" "$PWD/target/blender-site"
    done
fi
ls -l docs/*.png
