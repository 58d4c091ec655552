"""``rgbd:COLOR.png,DEPTH.png,INTRINSICS.json``: one registered RGBD frame from three files.

The depth PNG is uint16 in the units the intrinsics file states (``depth_scale``: 0.001 =
metres per unit, or 1000 = units per metre), millimetres when it states none. The
intrinsics file is Open3D's PinholeCameraIntrinsic JSON or ``{width, height, fx, fy, cx, cy}``.
The frame has index 0 and timestamp 0; depth and colour of different sizes, or of another
size than the intrinsics, raise :class:`~swarmpose.core.errors.SourceError` when opening.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from swarmpose.core.errors import ConfigError, SourceError
from swarmpose.sources.base import Frame, FrameSource, SkippedFrame
from swarmpose.sources.imagefiles import MILLIMETRES, check_pair, load_intrinsics, read_color, read_depth


class StillSource(FrameSource):
    """A single RGBD frame (``length`` = 1). ``frame`` is read when the source is opened."""

    def __init__(self, color: Path | str, depth: Path | str, intrinsics: Path | str, uri: str | None = None):
        self.uri = uri or f"rgbd:{color},{depth},{intrinsics}"
        self.length = 1
        intr, units = load_intrinsics(Path(intrinsics).expanduser())
        depth_m = read_depth(Path(depth).expanduser(), units or MILLIMETRES)
        rgb = read_color(Path(color).expanduser())
        mismatch = check_pair(depth_m, rgb, f"{depth} / {color} with {intrinsics}", intr)
        if mismatch:
            raise SourceError(mismatch)
        self.intrinsics = intr
        self.frame = Frame(0, 0, depth_m, rgb, intr)

    @classmethod
    def from_spec(cls, spec: str, uri: str | None = None) -> StillSource:
        """Parse ``COLOR,DEPTH,INTRINSICS`` (ConfigError when not three comma-separated paths)."""
        parts = [p.strip() for p in spec.split(",")]
        if len(parts) != 3 or not all(parts):
            raise ConfigError(f"rgbd: wants three comma-separated files COLOR.png,DEPTH.png,INTRINSICS.json, "
                              f"got {spec!r}")
        return cls(*parts, uri=uri)

    def _frames(self) -> Iterator[Frame | SkippedFrame]:
        yield self.frame
