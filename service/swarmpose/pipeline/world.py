"""Finding one camera's floor-aligned world frame while it runs (``--floor``, ``--coordinates``).

The world frame (y up, floor at y = 0, metres; axes in :mod:`swarmpose.core.world`) needs the
floor and an origin:

* **floor** — ``--floor auto`` fits it to the depth (:func:`swarmpose.detect.floor.fit_floor`,
  Open3D RANSAC) on every frame until one fits, for the first :data:`EAGER_FRAMES` frames, then
  on every :data:`RETRY_FRAMES`-th frame, and keeps the first good fit **fixed** from then on: a
  tracker's world must not wobble with a refit's noise, and a camera on a tripod does not move
  (a camera that moves needs a restart, or its extrinsics). A camera with new intrinsics (a
  different device reopened) forgets its floor and fits again. ``--floor FILE.json`` reads the
  floor, or the whole camera-to-world transform, from an extrinsics file (formats in
  :func:`swarmpose.core.world.parse_extrinsics`). ``--floor off``: no world frame at all;
* **origin** — on the floor straight below the root (pelvis) of the first body with a pose
  (``init`` or ``tracking``, the first listed) at the first frame where the floor is known,
  fixed from then on. A given ``camera_to_world`` brings its own origin and is used as it is.

The camera-to-world transform is None until both are known; frame messages carry it
(``camera_to_world``) and, with ``--coordinates world``, their joints and poses are in the world
frame from then on (``coordinates`` says which frame each message uses). The detection half
calls :meth:`WorldFrame.observe_depth` (the fit), the tracking half :meth:`WorldFrame.observe_bodies`
(the origin); each may run in its own thread.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.core.world import WorldState, load_extrinsics, world_from_floor
from swarmpose.detect.floor import FloorPlane, fit_floor
from swarmpose.sources.base import Frame

log = logging.getLogger(__name__)
COORDINATES = ("camera", "world")
EAGER_FRAMES = 30
"""The floor is fitted on every one of a camera's first this many frames until it fits..."""
RETRY_FRAMES = 30
"""...then on every this many-th frame (about 8 ms a fit at 640x480)."""
NOT_FITTED = object()
"""``observe_depth``'s ``fitted`` when nothing fitted the frame's floor yet."""


class WorldFrame:
    """The floor and camera-to-world transform of one camera (see the module docstring).

    floor: ``"auto"`` (fit to the depth) or the path of an extrinsics JSON file; coordinates:
    ``"camera"`` or ``"world"``, the frame wanted for messages, poses.jsonl and poses.csv.
    :attr:`state` is a :class:`~swarmpose.core.world.WorldState` (None: no floor yet), replaced
    whole, so another thread may read it at any time.
    """

    def __init__(self, floor: str = "auto", coordinates: str = "camera"):
        if coordinates not in COORDINATES:
            raise ConfigError(f"coordinates {coordinates!r}: choose one of {COORDINATES}")
        self.coordinates = coordinates
        self.auto = floor == "auto"
        self.state: WorldState | None = None if self.auto else load_extrinsics(floor)
        self._intrinsics: Intrinsics | None = None
        self._frames = 0
        self._lock = threading.Lock()

    def observe_depth(self, frame: Frame, fitted: FloorPlane | None | object = NOT_FITTED) -> None:
        """Fit the floor to ``frame``'s depth when it is not known yet and this frame is due;
        ``fitted``: what the segmentation's own fit of this frame found (a plane, or None: no
        floor in view), which spares a second fit; :data:`NOT_FITTED`: nothing fitted it yet."""
        if not self.auto:
            return
        with self._lock:
            if frame.intrinsics != self._intrinsics:  # a new camera: its own floor
                if self._intrinsics is not None:
                    log.info("the camera changed: fitting its floor again")
                self._intrinsics, self._frames, self.state = frame.intrinsics, 0, None
            self._frames += 1
            due = self.state is None and (self._frames <= EAGER_FRAMES or self._frames % RETRY_FRAMES == 0)
        if not due:
            return
        plane = fitted
        if plane is NOT_FITTED:
            try:
                plane = fit_floor(frame.depth, frame.intrinsics)
            except Exception as exc:  # a frame the fit cannot use: try a later one
                log.debug("frame %d: floor fit failed: %s", frame.index, exc)
                return
        if plane is None:
            return
        with self._lock:
            if self.state is None and frame.intrinsics == self._intrinsics:
                self.state = WorldState(np.asarray(plane.normal, dtype=np.float64), float(plane.offset), "depth",
                                        int(plane.inliers))
                log.info("floor found at frame %d: camera %.2f m above it, tilted %.1f degrees", frame.index,
                         plane.offset, plane.tilt_deg)

    def observe_bodies(self, bodies: Sequence) -> WorldState | None:
        """Set the origin below the first body with a pose once the floor is known; the state."""
        with self._lock:
            state = self.state
            if state is None or state.camera_to_world is not None:
                return state
            root = next((np.asarray(b.pose[0:3], dtype=np.float64) for b in bodies
                         if b.state != "lost" and b.pose is not None and np.all(np.isfinite(b.pose[0:3]))), None)
            if root is None:
                return state
            transform = world_from_floor(state.floor_normal, state.floor_offset_m, root)
            self.state = replace(state, camera_to_world=transform)
            return self.state

    def info(self) -> dict:
        """The info message's ``world``: ``coordinates``, ``floor`` and ``camera_to_world`` (None
        while unknown)."""
        state = self.state
        known = state.as_dict() if state is not None else {"floor": None, "camera_to_world": None}
        return {"coordinates": self.coordinates, **known}


def make_world(floor: str, coordinates: str) -> WorldFrame | None:
    """The world frame of the ``floor`` and ``coordinates`` settings (None for ``floor = off``);
    ConfigError for world coordinates without a floor, or a bad extrinsics file."""
    spec = str(floor).strip()
    if spec == "off":
        if coordinates == "world":
            raise ConfigError("--coordinates world needs a floor: use --floor auto (fitted to the depth) or "
                              "--floor EXTRINSICS.json, not --floor off")
        return None
    if not spec:
        raise ConfigError("--floor is empty: use auto (fitted to the depth), off, or an extrinsics JSON file")
    return WorldFrame(spec, coordinates)


__all__ = ["COORDINATES", "EAGER_FRAMES", "RETRY_FRAMES", "WorldFrame", "make_world"]
