"""A hard bend of meshes solved from rest and coarse to fine, one `rigidcells deform` process
each: the solve's iterations and seconds, the energy, and the fold-overs, from the report.

    python tools/python/coarse_to_fine.py BIN MODEL[,MODEL...] CELLS[,CELLS...] [LEVELS]

BIN is the rigidcells binary; each MODEL a mesh (the paper's: `../shared/data/meshes/horse.ply`,
`dragon_11k_binary.ply`, `bun_zipper.ply`, `mannequin.ply`); CELLS the `--cells` counts;
LEVELS the `--coarse-levels` compared (default `0,1`: from rest, one coarse stage). The edit
fixes the lowest 15 % of the model along its longest axis and turns the highest 15 % by 60°
about the next axis, lifting it by a fifth of the length along the third. The energy of each
run is printed relative to the first LEVELS' run.
"""

import json
import os
import re
import subprocess
import sys
import tempfile


def bounds(binary, model):
    """The model's box from `rigidcells info`."""
    out = subprocess.run([binary, "info", model], capture_output=True, text=True, check=True)
    b = re.search(r"bounds: x \[(\S+), (\S+)\]\s+y \[(\S+), (\S+)\]\s+z \[(\S+), (\S+)\]",
                  out.stdout)
    return [float(b.group(i)) for i in (1, 3, 5)], [float(b.group(i)) for i in (2, 4, 6)]


def bend(lo, hi):
    """The edit spec: the ends along the longest axis, a little beyond the box across it."""
    extent = [h - l for l, h in zip(lo, hi)]
    a = max(range(3), key=lambda i: extent[i])
    pad = [0.01 * extent[a]] * 3

    def box(t0, t1):
        low = [l - p for l, p in zip(lo, pad)]
        high = [h + p for h, p in zip(hi, pad)]
        low[a] = lo[a] + t0 * extent[a] - (pad[a] if t0 == 0 else 0)
        high[a] = lo[a] + t1 * extent[a] + (pad[a] if t1 == 1 else 0)
        return f"{{ min = {low}, max = {high} }}"

    axis = [0, 0, 0]
    axis[(a + 1) % 3] = 1
    lift = [0.0, 0.0, 0.0]
    lift[(a + 2) % 3] = 0.2 * extent[a]
    return (f"[[fixed]]\nbox = {box(0, 0.15)}\n[[handle]]\nbox = {box(0.85, 1)}\n"
            f"rotate = {{ axis = {axis}, degrees = 60 }}\ntranslate = {lift}\n")


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    binary, models = sys.argv[1], sys.argv[2].split(",")
    counts = [int(c) for c in sys.argv[3].split(",")]
    levels = sys.argv[4].split(",") if len(sys.argv) > 4 else ["0", "1"]
    with tempfile.TemporaryDirectory() as folder:
        spec, report = os.path.join(folder, "bend.toml"), os.path.join(folder, "r.json")
        for model in models:
            with open(spec, "w") as f:
                f.write(bend(*bounds(binary, model)))
            out = os.path.join(folder, "out" + os.path.splitext(model)[1])
            for n in counts:
                first, row = None, []
                for level in levels:
                    subprocess.run([binary, "deform", model, "--edit", spec, "-o", out, "--cells",
                                    str(n), "--coarse-levels", level, "--report", report, "-q"],
                                   check=True)
                    r = json.load(open(report))
                    energy = r["energy"][-1]
                    first = first or energy
                    row.append(f"levels {level}: {r['iterations']} its, "
                               f"{r['timings_s']['solve']:.2f} s, energy {energy:.9e} "
                               f"({(energy - first) / first:+.1e}), {r['foldovers']} folded")
                print(f"{os.path.basename(model)}, {r['cells']} cells: " + " | ".join(row),
                      flush=True)


if __name__ == "__main__":
    main()
