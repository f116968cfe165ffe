"""The add-on's work off Blender's main thread: a deformation (`DeformJob`) and a live session
(`LiveWorker`) on threads of their own, with no Blender data in them.

Blender's data may only be touched on its main thread. The operators read everything the
library needs there (vertices, triangles, the spec, the handles' poses), hand plain arrays and
dicts to these classes, and write their results back there, on a timer. The library releases
the GIL around every heavy call, so Blender stays responsive while the solver works.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, List, Optional, Tuple

import numpy as np


class Cancelled(Exception):
    """The artist stopped the work (Esc)."""


class DeformJob:
    """`rigidcells.deform` on a thread: `start`, then poll `done`; `cancel` stops it at the
    library's next step. Its `progress` is `(stage, done, total)` as last heard."""

    def __init__(self, points: np.ndarray, spec: dict, triangles: Any, options: dict) -> None:
        self._args = (points, spec, triangles, options)
        self._cancel = threading.Event()
        self.progress: Tuple[str, int, Optional[int]] = ("starting", 0, None)
        self.result: Optional[Tuple[np.ndarray, Any]] = None
        self.error: Optional[BaseException] = None
        self.thread = threading.Thread(target=self._run, name="rigidcells deform", daemon=True)

    def start(self) -> "DeformJob":
        self.thread.start()
        return self

    @property
    def done(self) -> bool:
        return not self.thread.is_alive() and (self.result is not None or self.error is not None)

    def cancel(self) -> None:
        self._cancel.set()

    def _heard(self, stage: str, done: int, total: Optional[int]) -> None:
        self.progress = (stage, done, total)
        if self._cancel.is_set():
            raise Cancelled("Rigid Cells: cancelled")

    def _run(self) -> None:
        import rigidcells

        points, spec, triangles, options = self._args
        try:
            self.result = rigidcells.deform(
                points, spec, triangles=triangles, progress=self._heard, **options
            )
        except BaseException as e:  # handed to the main thread, which reports it
            self.error = e


class LiveWorker:
    """A `rigidcells.Session` on a thread, following the handles' poses (and the pins'
    places) as the main thread hands them over (`move`): each new pose is a drag step (a few
    local-global iterations) and a blended preview. Once the poses have rested for `idle`
    seconds the solve goes on to convergence a refinement step at a time (not between the
    poses of a drag, where a step would delay the next pose's shape), and once converged and
    at rest for `settle` seconds the exact transfer is released. `take` gives the newest
    shape not yet taken, `("preview" | "released", positions)`. `finish` ends on the last
    pose's exact shape; `stop` ends at once."""

    def __init__(
        self,
        points: np.ndarray,
        spec: dict,
        triangles: Any,
        options: dict,
        settle: float = 0.25,
        idle: float = 0.05,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._args = (points, spec, triangles, options)
        self._settle, self._idle, self._clock = settle, min(idle, settle), clock
        self._wake = threading.Condition()
        self._pose: Optional[Tuple[List[dict], Any, Any]] = None
        self._moved_at = clock()
        self._finishing = self._stopping = False
        self._shape: Optional[Tuple[str, np.ndarray]] = None
        self.report: Any = None
        self.error: Optional[BaseException] = None
        self.cells = 0
        # Drag steps taken, and when each shape was published (for the updates per second).
        self.steps = 0
        self.published: List[float] = []
        self.thread = threading.Thread(target=self._run, name="rigidcells live", daemon=True)

    def start(self) -> "LiveWorker":
        self.thread.start()
        return self

    def move(
        self,
        poses: List[dict],
        pins: Optional[List[List[float]]] = None,
        targets: Optional[List[List[float]]] = None,
    ) -> None:
        """The handles' newest poses (one dict a handle), where the pins go now (one point a
        pin, or None) and where the weighted vertices pull (one point a target, or None); an
        older move not yet solved is dropped."""
        with self._wake:
            self._pose = (poses, pins, targets)
            self._moved_at = self._clock()
            self._wake.notify()

    def take(self) -> Optional[Tuple[str, np.ndarray]]:
        """The newest shape not yet taken."""
        with self._wake:
            shape, self._shape = self._shape, None
            return shape

    def finish(self) -> None:
        """Ends on the last pose, converged and released through the transfer."""
        with self._wake:
            self._finishing = True
            self._wake.notify()

    def stop(self) -> None:
        """Ends now, publishing nothing more."""
        with self._wake:
            self._stopping = True
            self._wake.notify()

    @property
    def done(self) -> bool:
        return not self.thread.is_alive()

    def _heard(self, _stage: str, _done: int, _total: Optional[int]) -> None:
        """The first solve's progress: `stop` ends it at the library's next step."""
        if self._stopping:
            raise Cancelled("Rigid Cells: Live stopped")

    def _publish(self, kind: str, positions: np.ndarray) -> None:
        with self._wake:
            if not self._stopping:
                self._shape = (kind, positions)
                self.published.append(self._clock())

    def _run(self) -> None:
        import rigidcells

        points, spec, triangles, options = self._args
        try:
            session = rigidcells.Session(
                points, spec, triangles=triangles, progress=self._heard, **options
            )
            self.cells = session.cells
            released = False
            while True:
                with self._wake:
                    while True:
                        if self._stopping:
                            return
                        pose, self._pose = self._pose, None
                        still = self._clock() - self._moved_at
                        if pose is not None:
                            break
                        if not session.converged:
                            # Refined once the handle rests (or the drag ends).
                            if still >= self._idle or self._finishing:
                                break
                            wait: Optional[float] = self._idle - still
                        elif not released and (still >= self._settle or self._finishing):
                            break
                        elif released and self._finishing:
                            return
                        else:
                            wait = None if released else self._settle - still
                        self._wake.wait(None if wait is None else max(0.0, wait))
                if pose is not None:
                    session.drag(pose[0], pins=pose[1], targets=pose[2])
                    released = False
                    # Published before counted: a step counted has its shape waiting.
                    self._publish("preview", session.preview())
                    self.steps += 1
                elif not session.converged:
                    session.refine()
                    self._publish("preview", session.preview())
                else:
                    moved, self.report = session.release()
                    released = True
                    self._publish("released", moved)
        except BaseException as e:  # handed to the main thread, which reports it
            self.error = e
