"""Builds the Blender extension: the add-on folder with the rigidcells wheel bundled, as the zip
Blender 4.2 and later install (Edit > Preferences > Get Extensions > Install from Disk).

    python3 blender/build_extension.py [WHEEL]

WHEEL defaults to the newest `target/wheels/rigidcells-*-abi3-*.whl` (`cd python && maturin
build --release -o ../target/wheels`). The manifest in the zip lists that wheel; the zip is
written to `target/rigidcells_blender-VERSION.zip`.
"""

import re
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "blender" / "rigidcells_blender"


def main() -> None:
    if len(sys.argv) > 1:
        wheel = Path(sys.argv[1])
    else:
        wheels = sorted((ROOT / "target" / "wheels").glob("rigidcells-*-abi3-*.whl"))
        if not wheels:
            sys.exit("no wheel: run `cd python && maturin build --release -o ../target/wheels`")
        wheel = max(wheels, key=lambda p: p.stat().st_mtime)
    manifest = (ADDON / "blender_manifest.toml").read_text(encoding="utf-8")
    manifest = re.sub(r"(?m)^wheels = \[.*\]$", f'wheels = ["./wheels/{wheel.name}"]', manifest)
    version = tomllib.loads(manifest)["version"]
    out = ROOT / "target" / f"rigidcells_blender-{version}.zip"
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("blender_manifest.toml", manifest)
        for f in sorted(ADDON.glob("*.py")):
            z.write(f, f.name)
        z.write(wheel, f"wheels/{wheel.name}")
    print(out)


if __name__ == "__main__":
    main()
