"""Builds the Blender add-on, with the rigidcells package bundled, in two zips:

- `target/rigidcells_blender-VERSION.zip`, the extension Blender 4.2 and later install (Edit >
  Preferences > Get Extensions > Install from Disk): the add-on's files, its manifest listing
  the wheel, and the wheel, which Blender installs;
- `target/rigidcells_blender-VERSION-legacy.zip`, the add-on as Blender 3.4 to 4.1 install it
  (Edit > Preferences > Add-ons > Install…; later versions too): the folder
  `rigidcells_blender/`, described by its `bl_info`, with the wheel's package unpacked in
  `rigidcells_blender/site/`, which the add-on puts on Python's path.

    python3 blender/build_extension.py [WHEEL]

WHEEL defaults to the newest `target/wheels/rigidcells-*-abi3-*.whl` (`cd python && maturin
build --release -o ../target/wheels`). The two zips' paths are printed.
"""

import ast
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
    legacy_version = ".".join(map(str, bl_info()["version"]))
    if legacy_version != version:
        sys.exit(f"bl_info's version {legacy_version} is not the manifest's {version}")
    out = ROOT / "target" / f"rigidcells_blender-{version}.zip"
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("blender_manifest.toml", manifest)
        for f in sorted(ADDON.glob("*.py")):
            z.write(f, f.name)
        z.write(wheel, f"wheels/{wheel.name}")
    print(out)
    legacy = ROOT / "target" / f"rigidcells_blender-{version}-legacy.zip"
    with zipfile.ZipFile(legacy, "w", zipfile.ZIP_DEFLATED) as z, zipfile.ZipFile(wheel) as w:
        for f in sorted(ADDON.glob("*.py")):
            z.write(f, f"rigidcells_blender/{f.name}")
        # The package, not its metadata: what `import rigidcells` finds on the path.
        for item in w.infolist():
            if item.filename.startswith("rigidcells/"):
                z.writestr(f"rigidcells_blender/site/{item.filename}", w.read(item))
    print(legacy)


def bl_info() -> dict:
    """The add-on's `bl_info`, read from its source without Blender."""
    tree = ast.parse((ADDON / "__init__.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "bl_info" for t in node.targets
        ):
            return ast.literal_eval(node.value)
    sys.exit("the add-on has no bl_info")


if __name__ == "__main__":
    main()
