"""rigidcells.dask on LocalClusters of 2 worker processes: apply_tiles over 16 tiles, every
output byte-identical to the command line's `apply` of that tile; solve_tiles over them, the
field of the same subdomains solved in one process, and a worker lost mid-solve leaving
nothing written."""

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import rigidcells
from test_rigidcells import ROOT, SHARED, cli

distributed = pytest.importorskip("dask.distributed")
import dask  # noqa: E402
pytest.importorskip("laspy")
sys.path.insert(0, str(ROOT / "tools" / "python"))
from tiles import cut as cut_tiles  # noqa: E402


def test_apply_tiles_on_a_local_cluster_matches_the_cli(tmp_path):
    src = SHARED / "las" / "autzen_trim.laz"
    tiles = cut_tiles(src, tmp_path)
    assert len(tiles) == 16
    spec = {
        "fixed": [{"box": {"min": [636000, 848900, 0], "max": [636300, 849600, 1000]}}],
        "handle": [{"box": {"min": [636900, 848900, 0], "max": [637200, 849600, 1000]}, "translate": [0, 0, 20]}],
    }
    field = tmp_path / "bend.field"
    rigidcells.deform_file(src, tmp_path / "whole.laz", spec, save_field=field)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster:
        with distributed.Client(cluster) as client:
            t = time.perf_counter()
            infos = rigidcells.dask.apply_tiles(field, tiles, tmp_path / "out", client)
            seconds = time.perf_counter() - t
    assert [Path(i["tile"]) for i in infos] == tiles
    total = sum(i["samples"] for i in infos)
    assert total == 110000
    print(f"dask: 16 tiles, {total} points in {seconds:.2f} s")
    for tile in tiles:
        ref = tmp_path / f"cli_{tile.name}"
        subprocess.run([cli(), "apply", str(field), str(tile), "-o", str(ref), "-q"], check=True)
        assert (tmp_path / "out" / tile.name).read_bytes() == ref.read_bytes(), tile.name


def test_a_tile_the_library_refuses_is_not_run_again(tmp_path, monkeypatch):
    from test_rigidcells import bar_points

    pts = bar_points()
    field = tmp_path / "bar.field"
    rigidcells.solve(pts, {"fixed": [{"box": {"min": [-1, -1, -1], "max": [1, 2, 2]}}]}).save(field)
    inside, outside = tmp_path / "inside.xyz", tmp_path / "outside.xyz"
    inside.write_text("".join(f"{x} {y} {z}\n" for x, y, z in pts[:50]))
    outside.write_text("".join(f"{x + 1000} {y} {z}\n" for x, y, z in pts[:50]))
    runs = []
    apply_file = rigidcells.apply_file

    def counted(field, tile, *args, **kwargs):
        runs.append(Path(tile).name)
        return apply_file(field, tile, *args, **kwargs)

    # Workers in this process (threads), so that they call the counted apply_file.
    monkeypatch.setattr(rigidcells, "apply_file", counted)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False) as cluster:
        with distributed.Client(cluster) as client:
            with pytest.raises(ValueError, match="outside.xyz: 50 samples lie farther"):
                rigidcells.dask.apply_tiles(field, [outside], tmp_path / "out", client)
            # An I/O error may pass: it is tried again.
            with pytest.raises(OSError):
                rigidcells.dask.apply_tiles(
                    field, [tmp_path / "gone.xyz"], tmp_path / "out", client, retries=1
                )
            infos = rigidcells.dask.apply_tiles(field, [inside], tmp_path / "out", client)
    assert runs == ["outside.xyz", "gone.xyz", "gone.xyz", "inside.xyz"]
    assert infos[0]["samples"] == 50


AUTZEN_BEND = {
    "fixed": [{"box": {"min": [636000, 848900, 0], "max": [636300, 849600, 1000]}}],
    "handle": [
        {"box": {"min": [636900, 848900, 0], "max": [637200, 849600, 1000]}, "translate": [0, 0, 20]}
    ],
}


# Cells of the solves on workers: few, for the test's time (each iteration of the solve is a
# round trip to the workers).
CELL = 40.0


def _moved(field, points):
    return rigidcells.Field.load(field).apply(points)


def test_solve_tiles_on_worker_processes_gives_the_one_process_field(tmp_path):
    """Four subdomains on two worker processes: the field of the same split solved in one
    process, to rounding, and the minimum of the default solve (Gauss-Newton's) within a
    thousandth of a cell and a millionth of the energy."""
    src = SHARED / "las" / "autzen_trim.laz"
    tiles = cut_tiles(src, tmp_path)
    laspy = pytest.importorskip("laspy")
    las = laspy.read(src)
    points = np.column_stack([las.x, las.y, las.z])[::7]
    common = dict(cell_size=CELL, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster:
        with distributed.Client(cluster) as client:
            report = rigidcells.dask.solve_tiles(
                tiles, AUTZEN_BEND, tmp_path / "dask.field", client, subdomains=4, **common
            )
            with pytest.raises(ValueError, match="subdomains must be 1 or more, got 0"):
                rigidcells.dask.solve_tiles(
                    tiles, AUTZEN_BEND, tmp_path / "no.field", client, subdomains=0
                )
    assert report.linear_solver == "local-global"
    rigidcells.solve_files(tiles, AUTZEN_BEND, tmp_path / "here.field", subdomains=4, **common)
    default = rigidcells.solve_files(tiles, AUTZEN_BEND, tmp_path / "default.field", **common)
    dask, here, minimum = (
        _moved(tmp_path / f"{name}.field", points) for name in ("dask", "here", "default")
    )
    assert np.abs(dask - here).max() <= 1e-9 * CELL
    assert np.abs(dask - minimum).max() <= 1e-3 * CELL
    assert abs(report.energy[-1] - default.energy[-1]) <= 1e-6 * default.energy[-1]
    assert np.abs(dask - points).max() > 10.0  # the handle moved the east end by 20 m


def test_a_worker_lost_mid_solve_ends_it_with_nothing_written(tmp_path):
    src = SHARED / "las" / "autzen_trim.laz"
    field = tmp_path / "lost.field"
    # A dead worker's connection is given up after 3 s, not Dask's default 30.
    quick = dask.config.set({"distributed.comm.timeouts.connect": "3s"})
    with quick, distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster:
        with distributed.Client(cluster) as client:
            victim = sorted(client.scheduler_info()["workers"])[1]
            killed = []

            def progress(stage, done, total):
                if stage.startswith("solving") and not killed:
                    killed.append(stage)
                    client.run(os._exit, 1, workers=[victim], on_error="ignore")

            with pytest.raises(rigidcells.dask.WorkerLost, match="lost mid-solve"):
                rigidcells.dask.solve_tiles(
                    [src], AUTZEN_BEND, field, client, subdomains=4, cell_size=CELL,
                    progress=progress, report=tmp_path / "lost.json",
                )
    assert killed
    assert not field.exists() and not (tmp_path / "lost.json").exists()
