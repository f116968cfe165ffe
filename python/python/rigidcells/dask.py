"""Tiles on a Dask cluster: ``solve_tiles`` solves an edit over tiles with the solver's global
step split into subdomains held by the cluster's workers, and ``apply_tiles`` maps
``rigidcells.apply_file`` over tiles, one task per tile, each written to
``out_dir/<the tile's file name>``.

**The solve by subdomains.** ``solve_tiles`` solves by local-global iterations (the option
``subdomains``): each global step is a linear system of the cells' positions, solved by
conjugate gradients preconditioned by a two-level additive Schwarz method — the cells cut into
``subdomains`` compact runs of a space-filling curve, each grown by a layer of neighbours. Each
subdomain's block is sent once per system to one worker (an actor that factors it and keeps
the factor), and every iteration sends each worker its blocks' right-hand sides and takes
their solutions back; the small coarse problem every subdomain shares is solved by the
calling process, which also runs the iterations, the local steps and the transfer. The
iterations are those of a solve in one process with as many subdomains, to rounding, and the
field written is the one ``rigidcells.solve_files(..., subdomains=k)`` writes. A worker lost
mid-solve ends the call with an error that says so, and the field and report are not written.

Outputs are written atomically (a temporary file renamed over the target) and are a
deterministic function of the field and the tile, so a task that a worker's loss or a passing
I/O error makes Dask run again writes the same bytes: retries are safe. A tile the library
refuses (``ValueError``, which ``FormatError`` is, or ``TypeError``: a tile outside the field, a
malformed file, a bad argument) fails the same way every time, so it is not run again: its
task returns the error instead of raising it, and ``apply_tiles`` raises it at once.
"""

from __future__ import annotations

import asyncio
import os
from pathlib import Path
from typing import Any, Iterable, List, Optional, Union

PathLike = Union[str, "os.PathLike[str]"]


class WorkerLost(RuntimeError):
    """A worker holding subdomains failed mid-solve; nothing was written."""


class _Blocks:
    """An actor on one worker: the factors of the subdomains' blocks sent to it."""

    def __init__(self) -> None:
        self._factors: list = []

    def factor(self, blocks: list) -> int:
        from rigidcells import _rigidcells

        self._factors = [_rigidcells.BlockFactor(*b) for b in blocks]
        return sum(len(f) for f in self._factors)

    def solve(self, rhs: list) -> list:
        return [f.solve(r) for f, r in zip(self._factors, rhs)]


# Errors by which Dask says a worker or its connection is gone (an actor whose worker died, a
# closed comm, a call that outlived its timeout); what an actor's own method raises passes
# through as it was raised.
_LOST = (RuntimeError, OSError, TimeoutError, asyncio.TimeoutError, asyncio.CancelledError)


class _Factored:
    """The blocks of one system, factored by actors: block ``k`` lives on actor
    ``k % len(actors)``."""

    def __init__(self, actors: list, timeout: float) -> None:
        self._actors, self._timeout = actors, timeout

    def solve(self, rhs: list) -> list:
        n = len(self._actors)
        answers = _on_actors(self._actors, "solve", [rhs[i::n] for i in range(n)], self._timeout)
        out: list = [None] * len(rhs)
        for i, solved in enumerate(answers):
            out[i::n] = solved
        return out


def _lost(e: BaseException) -> "WorkerLost":
    return WorkerLost(
        f"a Dask worker holding subdomains was lost mid-solve ({type(e).__name__}: {e}); "
        "the field was not written"
    )


def _on_actors(actors: list, method: str, arguments: list, timeout: float) -> list:
    """``actor.method(argument)`` on every actor at once, their results in order; a lost
    worker, or a call past ``timeout`` seconds, raised as ``WorkerLost``."""
    try:
        calls = [getattr(a, method)(x) for a, x in zip(actors, arguments)]
        return [c.result(timeout=timeout) for c in calls]
    except _LOST as e:
        raise _lost(e) from e


class _Workers:
    """The cluster's workers as the solver's subdomain workers: one actor on each worker
    alive when a system is factored, made anew for each system."""

    def __init__(self, client: Any, timeout: float) -> None:
        self._client, self._timeout = client, timeout
        self.addresses()

    def addresses(self) -> List[str]:
        """The workers alive now."""
        addresses = sorted(self._client.scheduler_info()["workers"])
        if not addresses:
            raise WorkerLost("the Dask cluster has no workers")
        return addresses

    def factor(self, blocks: list) -> _Factored:
        addresses = self.addresses()
        n = min(len(addresses), len(blocks)) or 1
        futures = [
            self._client.submit(_Blocks, actor=True, workers=[a], pure=False)
            for a in addresses[:n]
        ]
        try:
            actors = [f.result(timeout=self._timeout) for f in futures]
        except _LOST as e:
            raise _lost(e) from e
        _on_actors(actors, "factor", [blocks[i::n] for i in range(n)], self._timeout)
        return _Factored(actors, self._timeout)


def _own_client(client: Any) -> Any:
    """``client``, the current one, or a new ``LocalCluster`` of worker processes (returned
    second, to close)."""
    from dask.distributed import Client, LocalCluster, get_client

    if client is not None:
        return client, None
    try:
        return get_client(), None
    except ValueError:
        own = Client(LocalCluster(processes=True))
        return own, own


def _close(own: Any) -> None:
    if own is not None:
        cluster = own.cluster
        own.close()
        cluster.close()


def solve_tiles(
    tiles: Union[PathLike, Iterable[PathLike]],
    spec: Any,
    save_field: PathLike,
    client: Any = None,
    *,
    subdomains: Optional[int] = None,
    timeout: float = 600.0,
    **arguments: Any,
) -> Any:
    """``rigidcells.solve_files(tiles, spec, save_field, subdomains=..., **arguments)`` with
    the subdomains' blocks factored and solved by the workers of a ``dask.distributed``
    cluster (see the module's docs); returns its ``Report``.

    ``client``: a ``dask.distributed.Client``; ``None`` takes the current one, or starts a
    ``LocalCluster`` of worker processes for the call. ``subdomains``: how many, 1 or more
    (default: the workers' count, at least 2); block ``k`` goes to the ``k mod W``-th of the
    ``W`` workers alive when a system is factored. ``timeout``: seconds a worker may take to
    answer one call before it counts as lost. ``arguments``: those of ``solve_files``
    (``report``, ``cell_size``, ``memory_limit``, ``progress``, ...), but ``solver``, which is
    local-global here. A worker lost mid-solve raises ``WorkerLost``, and nothing is written.
    """
    import inspect

    import rigidcells

    if "solver" in arguments and arguments["solver"] not in (None, "local-global"):
        raise ValueError(
            f"solver={arguments['solver']!r}: solve_tiles solves by local-global iterations"
        )
    if subdomains is not None and (isinstance(subdomains, bool) or not isinstance(subdomains, int)):
        raise TypeError(f"subdomains must be a whole number, got {type(subdomains).__name__}")
    if subdomains is not None and subdomains < 1:
        raise ValueError(f"subdomains must be 1 or more, got {subdomains}")
    if not timeout > 0:
        raise ValueError(f"timeout must be a number of seconds above 0, got {timeout}")
    client, own = _own_client(client)
    try:
        workers = _Workers(client, timeout)
        if subdomains is None:
            subdomains = max(2, len(workers.addresses()))
        bound = inspect.signature(rigidcells.solve_files).bind(
            tiles, spec, save_field, subdomains=subdomains, **arguments
        )
        bound.apply_defaults()
        return rigidcells._solve_files(dict(bound.arguments), workers)
    finally:
        _close(own)


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
    from dask.distributed import as_completed

    tiles = [os.fspath(t) for t in tiles]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outputs = [os.fspath(out / Path(t).name) for t in tiles]
    if len(set(outputs)) != len(outputs):
        raise ValueError("two tiles have the same file name; their outputs would collide")
    client, own = _own_client(client)
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
        _close(own)
