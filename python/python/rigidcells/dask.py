"""Tiles on a Dask cluster: ``apply_tiles`` maps ``rigidcells.apply_file`` over tiles, one task
per tile, each written to ``out_dir/<the tile's file name>``.

Outputs are written atomically (a temporary file renamed over the target) and are a
deterministic function of the field and the tile, so a task that a worker's loss or a passing
I/O error makes Dask run again writes the same bytes: retries are safe. A tile the library
refuses (``ValueError``, which ``FormatError`` is, or ``TypeError``: a tile outside the field, a
malformed file, a bad argument) fails the same way every time, so it is not run again: its
task returns the error instead of raising it, and ``apply_tiles`` raises it at once.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, List, Optional, Union

PathLike = Union[str, "os.PathLike[str]"]


class _Refused:
    """A tile's error that running the tile again would only repeat (returned by its task, so
    that Dask does not retry it)."""

    def __init__(self, error: BaseException) -> None:
        self.error = error


def _apply_one(field: str, tile: str, output: str, outside: str) -> Union[dict, _Refused]:
    import rigidcells

    try:
        info = rigidcells.apply_file(field, tile, output, outside=outside)
    except (ValueError, TypeError) as e:
        return _Refused(e)
    info["tile"] = tile
    info["output"] = output
    return info


def apply_tiles(
    field: PathLike,
    tiles: Iterable[PathLike],
    out_dir: PathLike,
    client=None,
    *,
    outside: str = "refuse",
    retries: int = 2,
) -> List[dict]:
    """Applies the saved ``field`` to every tile on a ``dask.distributed`` cluster and returns
    what each ``apply_file`` did, in the tiles' order.

    ``client``: a ``dask.distributed.Client``; ``None`` takes the current one, or starts a
    ``LocalCluster`` of worker processes for the call. Tile names must be distinct (the
    outputs are named after them). A tile that fails raises its exception here: one the
    library refused (a ``ValueError`` or ``TypeError``) at once, any other after ``retries``
    more tries; the tiles still running are cancelled.
    """
    from dask.distributed import Client, LocalCluster, as_completed, get_client

    tiles = [os.fspath(t) for t in tiles]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outputs = [os.fspath(out / Path(t).name) for t in tiles]
    if len(set(outputs)) != len(outputs):
        raise ValueError("two tiles have the same file name; their outputs would collide")
    own: Optional[Client] = None
    if client is None:
        try:
            client = get_client()
        except ValueError:
            own = client = Client(LocalCluster(processes=True))
    try:
        futures = client.map(
            _apply_one,
            [os.fspath(field)] * len(tiles),
            tiles,
            outputs,
            [outside] * len(tiles),
            pure=False,
            retries=retries,
        )
        try:
            for future in as_completed(futures):
                done = future.result()
                if isinstance(done, _Refused):
                    raise done.error
        except BaseException:
            client.cancel(futures)
            raise
        return client.gather(futures)
    finally:
        if own is not None:
            cluster = own.cluster
            own.close()
            cluster.close()
