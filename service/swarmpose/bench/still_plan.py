"""What ``swarmpose bench still`` films and measures (:mod:`swarmpose.bench.still` runs it): the
plan alone, so that the command line reads its defaults without importing the tracker."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

from swarmpose.bench.matrix import DETECTORS
from swarmpose.core.errors import ConfigError
from swarmpose.sim.steadiness import LAG_WINDOW_S, MAX_LAG_S

STILL_CLIP = "mocap/bvh11_131_01.bvh"
"""CMU 131_01 (start, walk, stop): its first frame stands, and the walk sets off from it at once."""
SMOOTHINGS = ("off", "one-euro", "centred")
RUNS = ("one-euro", "centred")
"""The smoothing of each tracking run; both give the unsmoothed track too."""


@dataclass(frozen=True)
class StillPlan:
    """What ``bench still`` films: the clip (below the assets folder, a path, or ``builtin:NAME``), the
    held frame's time in it and how long it is held (s), the seconds of motion after it, the
    seconds of the track's start left out of the still frames, the body (``makehuman``: the
    assets' MakeHuman body; else a body spec), its shapes, the camera yaws (degrees) and the
    detectors (names of :data:`~swarmpose.bench.matrix.DETECTORS`)."""

    clip: str = STILL_CLIP
    at_s: float = 0.0
    hold_s: float = 3.0
    moving_s: float = 1.0
    settle_s: float = 0.5
    body: str = "makehuman"
    shapes: tuple[str, ...] = ("male", "female")
    yaws: tuple[float, ...] = (0.0, 90.0)
    detectors: tuple[str, ...] = ("simulated", "movenet")
    fps: float = 30.0

    @property
    def moves_at(self) -> int:
        """The first moving frame (the held frames are 0 .. moves_at - 1)."""
        return int(round(self.hold_s * self.fps))

    @property
    def frames(self) -> int:
        return self.moves_at + int(round(self.moving_s * self.fps))

    @property
    def settle(self) -> int:
        return int(round(self.settle_s * self.fps))

    def validate(self) -> None:
        """ConfigError for a plan whose still frames or motion are too short to measure."""
        reach = int(math.ceil(MAX_LAG_S * self.fps)) + 1
        if self.moves_at - max(self.settle, reach) < 2 or self.settle < 0:
            raise ConfigError(f"--hold {self.hold_s:g} s leaves fewer than 2 still frames after --settle "
                              f"{self.settle_s:g} s and the lag's {reach} frames; hold longer")
        if self.frames - self.moves_at < int(round(LAG_WINDOW_S * self.fps)) + reach:
            raise ConfigError(f"--moving {self.moving_s:g} s is too short for the lag's {LAG_WINDOW_S:g} s window "
                              f"and its {MAX_LAG_S:g} s search; give at least {LAG_WINDOW_S + MAX_LAG_S + 0.05:g} s")
        unknown = [d for d in self.detectors if d not in DETECTORS]
        if unknown or not self.detectors:
            raise ConfigError(f"unknown detector {unknown[0] if unknown else '(none)'!r}; choose from "
                              f"{', '.join(DETECTORS)}")
        if not self.shapes or not self.yaws:
            raise ConfigError("bench still needs at least one shape and one yaw")

    def needs_assets(self) -> bool:
        """Whether the body, clip or a detector comes from the shared assets folder."""
        return (self.body == "makehuman" or not (self.clip.startswith("builtin:") or Path(self.clip).is_absolute())
                or any(d != "simulated" for d in self.detectors))

    def describe(self) -> dict:
        """The plan's fields a record is made with (not the lists it runs over)."""
        return {k: v for k, v in asdict(self).items() if k not in ("shapes", "yaws", "detectors")}
