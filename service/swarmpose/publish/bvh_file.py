"""The BVH files of a run: :class:`BvhSink` (one body id's animation of the tracking body's bone
rig) and :class:`PerIdBvhSink` (one file per body id: ``poses.bvh`` for id 0,
``poses_id<N>.bvh`` for id N).

Centimetres, Y up: the floor-aligned world frame (:mod:`swarmpose.core.world`) of every message
that knows it (``camera_to_world``, or world ``coordinates``), else the camera frame turned
upright (:data:`CAMERA_TO_BVH`). Each row is written and flushed at once and the ``Frames:``
count rewritten in place, so the file is a complete BVH after every frame.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable
from dataclasses import fields
from pathlib import Path

import numpy as np

from swarmpose.body.kinematics import forward_kinematics
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.errors import ConfigError, OutputError, ShapeError
from swarmpose.core.rotations import zxy_euler_deg
from swarmpose.core.world import check_rigid
from swarmpose.publish.file_sink import FileSink, write_error
from swarmpose.sources.base import Frame

log = logging.getLogger(__name__)

CAMERA_TO_BVH = np.diag([1.0, -1.0, -1.0])
"""Camera frame (y down, z forward) -> BVH world (Y up): 180 degrees about x; used where the
floor is not known (a level camera's world frame)."""
BVH_UNITS_PER_M = 100.0
FRAMES_WIDTH = 10
"""Digits reserved for the ``Frames:`` count, rewritten in place after every frame."""
UPRIGHT = (0.0, 1.0, 0.0, 0.0)
"""Root quaternion of a body upright facing the camera (upright, facing +Z, in the BVH)."""
KEPT_POSES = 20_000
"""Rows with a pose whose poses a BVH file that may still change its body keeps (``--personalize``
locks a shape after 3..300 tracked frames; a person may come into view long after the file
starts): a new body rewrites those rows from the poses (float32, 144 bytes each), rows after
them stay as written."""

BodyOf = Callable[[int], SkinnedBody | None]
"""The body a body id is tracked with now (None: none tracks that id)."""


def same_rig(a, b) -> bool:
    """Whether rig ``b`` equals the :class:`~swarmpose.body.kinematics.Rig` ``a`` array by array."""
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name, None)) for f in fields(a))


def depth_first(parents: np.ndarray) -> list[int]:
    """Bone indices (B,) in depth-first order (children in index order): the order BVH lists them."""
    children: list[list[int]] = [[] for _ in parents]
    for bone, parent in enumerate(parents):
        if parent >= 0:
            children[int(parent)].append(bone)
    order, stack = [], [0]
    while stack:
        bone = stack.pop()
        order.append(bone)
        stack.extend(reversed(children[bone]))
    return order


def _numbers(values) -> str:
    return " ".join(f"{round(float(v), 6) + 0.0:.6f}" for v in values)  # + 0.0 turns -0.0 into 0.0


def bvh_path(out_dir: str | Path, body_id: int) -> Path:
    """The BVH file of body id ``body_id`` in ``out_dir``: ``poses.bvh`` for id 0 (what a run of
    one person writes), ``poses_id<N>.bvh`` for id N."""
    return Path(out_dir) / ("poses.bvh" if body_id == 0 else f"poses_id{body_id}.bvh")


def _check_id(body_id, what: str) -> int:
    """``body_id`` as an int; OutputError naming ``what`` unless it is an integer >= 0."""
    if isinstance(body_id, bool) or not isinstance(body_id, (int, np.integer)) or body_id < 0:
        raise OutputError(f"{what}: body id {body_id!r} is not an integer >= 0, so it names no BVH file; "
                          "give every body a track id as protocol/frame.schema.json says")
    return int(body_id)


class BvhSink(FileSink):
    """A BVH file of one body id's pose per frame as an animation of ``body``'s bone rig.

    Units centimetres; world frame Y up: the floor-aligned world frame of
    :mod:`swarmpose.core.world` (floor at Y = 0, origin under the person's start, X the camera's
    x on the floor, Z towards the camera) for every message that carries its
    ``camera_to_world`` (or is in world ``coordinates``); otherwise the camera frame turned 180
    degrees about x (x right, y up, z towards the camera). ROOT = bone 0 with position and ZXY rotation
    channels, every other bone a JOINT with ZXY rotation channels; OFFSETs are the rest
    bone heads relative to the parent's (the root's is zero: its position channels place
    it), leaf bones end in an End Site along the bone. Each bone's rotation is its delta
    from the rest pose, so all angles zero is the body's rest pose standing upright.
    One MOTION row per frame message, from the body of that message whose ``id`` is
    ``body_id`` (the first such); a frame without its pose (no body of that id, pose null)
    repeats the last row, or before any pose shows the rest pose upright at the origin (standing
    on the floor where the message knows the world frame). Frame
    Time is ``1 / fps``. The ``Frames:`` count is rewritten in place after every row, so the
    file is a complete BVH after every frame.
    """

    what = "the BVH file"

    def __init__(self, path: str | Path, body: SkinnedBody, fps: float = 30.0, body_id: int = 0,
                 may_change: bool = False) -> None:
        if not (np.isfinite(fps) and fps > 0):
            raise OutputError(f"BVH file {path}: fps must be positive, got {fps}")
        self.body_id = _check_id(body_id, f"BVH file {path}")
        super().__init__(path, "wb")
        self.fps = fps
        self.body = body
        self.rig = body.rig
        self.order = depth_first(self.rig.parents)
        self._last: str | None = None
        self._poses: list[tuple[np.ndarray | None, np.ndarray]] | None = [] if may_change else None
        self._kept_posed = 0
        self.floor_known = False
        """Whether any frame's message placed the motion on a floor (the world frame)."""
        try:
            self._file.write(self._header(fps).encode("ascii"))
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
        self._flush()

    def use_body(self, body: SkinnedBody) -> bool:
        """Animate ``body`` from now on, and the rows already written too: another shape of the
        same rig (the body ``--personalize`` locks). The file is rewritten with ``body``'s
        skeleton and the rows of the kept poses (:data:`KEPT_POSES`) recomputed on it (any
        later ones as written, with a warning), then replaces the old one at once; a rewrite
        that fails leaves the file and the sink as they were. Returns whether anything changed;
        a rig with other bones is refused (OutputError)."""
        self._check_open()
        if body is self.body or same_rig(self.rig, body.rig):
            self.body, self.rig = body, body.rig
            return False
        if not np.array_equal(body.rig.parents, self.rig.parents):
            raise OutputError(f"BVH file {self.path}: body {body.name} has other bones than {self.body.name}; "
                              "a BVH file animates one skeleton")
        saved = (self.body, self.rig, self._last, self._count_at)  # what the rewrite changes
        temporary = self.path.with_name(self.path.name + ".tmp")
        try:
            rows = self._written_rows()
            self.body, self.rig = body, body.rig
            kept = self._poses or []
            self._last = None
            for k, (pose, to_bvh) in enumerate(kept):
                rows[k] = self._last = self._pose_row(pose, to_bvh)
            if len(kept) < len(rows):
                log.warning("%s: the body changed after %d rows; the %d rows after the first %d keep their "
                            "angles on the old skeleton", self.path, len(rows), len(rows) - len(kept), len(kept))
            head = self._header(self.fps)
            with open(temporary, "wb") as out:
                out.write(head.replace(f"Frames: {0:<{FRAMES_WIDTH}d}", f"Frames: {len(rows):<{FRAMES_WIDTH}d}")
                          .encode("ascii"))
                out.write("".join(row + "\n" for row in rows).encode("ascii"))
            os.replace(temporary, self.path)  # the old file stays open until this succeeded
        except OSError as exc:
            self.body, self.rig, self._last, self._count_at = saved
            with contextlib.suppress(OSError):  # a partial temporary file, not what stood in its way
                if temporary.is_file():
                    temporary.unlink()
            raise write_error(self.what, self.path, exc) from exc
        old = self._file  # the poses stay kept: the body may change again (a new person's fit)
        try:
            old.close()
            self._file = open(self.path, "r+b")
            self._file.seek(0, 2)
        except OSError as exc:
            self._closed = True  # the new file is complete; this sink cannot append to it
            raise write_error(self.what, self.path, exc) from exc
        self._last = rows[-1] if rows else None
        return True

    def _header(self, fps: float) -> str:
        parents, heads = self.rig.parents, self.rig.heads * BVH_UNITS_PER_M
        has_child = np.zeros(len(parents), dtype=bool)
        has_child[parents[parents >= 0]] = True
        lines = ["HIERARCHY"]
        depth = {0: 0}
        open_bones: list[int] = []
        for bone in self.order:
            parent = int(parents[bone])
            while open_bones and open_bones[-1] != parent:  # close the finished subtrees
                lines.append("  " * depth[open_bones.pop()] + "}")
            depth[bone] = 0 if parent < 0 else depth[parent] + 1
            pad = "  " * depth[bone]
            name = "_".join(str(self.body.bone_names[bone]).split()) or f"bone{bone}"
            if parent < 0:
                lines += [f"ROOT {name}", pad + "{", pad + "  OFFSET " + _numbers((0.0, 0.0, 0.0)),
                          pad + "  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
            else:
                lines += [f"{pad}JOINT {name}", pad + "{", pad + "  OFFSET " + _numbers(heads[bone] - heads[parent]),
                          pad + "  CHANNELS 3 Zrotation Xrotation Yrotation"]
            if not has_child[bone]:
                lines += [pad + "  End Site", pad + "  {", pad + "    OFFSET " + _numbers(self._end_site(bone)),
                          pad + "  }"]
            open_bones.append(bone)
        while open_bones:
            lines.append("  " * depth[open_bones.pop()] + "}")
        lines += ["MOTION", "Frames: "]
        head = "\n".join(lines)
        self._count_at = len(head.encode("ascii"))
        return head + f"{0:<{FRAMES_WIDTH}d}\nFrame Time: {1.0 / fps:.8f}\n"

    def _end_site(self, bone: int) -> np.ndarray:
        """End Site offset (3,) cm of a leaf bone: half its parent segment along it, 1..10 cm;
        5 cm down where the segment is degenerate."""
        parent = int(self.rig.parents[bone])
        segment = BVH_UNITS_PER_M * (self.rig.heads[bone] - self.rig.heads[max(parent, 0)])
        length = float(np.linalg.norm(segment))
        if parent < 0 or length < 1e-6:
            return np.array([0.0, -5.0, 0.0])
        return segment / length * float(np.clip(0.5 * length, 1.0, 10.0))

    def channels(self, h: np.ndarray, to_bvh: np.ndarray | None = None) -> np.ndarray:
        """Channel values (6 + 3 (B - 1),) of pose ``h`` (36,) in file order: root position (cm,
        BVH world), then each bone's Z, X, Y rotation (degrees) relative to its parent. to_bvh:
        the (4, 4) rigid transform from the pose's frame to the BVH world (None:
        :data:`CAMERA_TO_BVH`)."""
        to_bvh = bvh_transform(None) if to_bvh is None else np.asarray(to_bvh, dtype=np.float64)
        turn, shift = to_bvh[:3, :3], to_bvh[:3, 3]
        rot, pos = forward_kinematics(self.rig, np.asarray(h, dtype=np.float64)[None])
        rot, pos = rot[0], pos[0]
        parents = self.rig.parents
        local = np.empty_like(rot)
        local[0] = turn @ rot[0]
        local[1:] = np.swapaxes(rot[parents[1:]], -1, -2) @ rot[1:]
        euler = zxy_euler_deg(local[self.order])
        return np.concatenate([BVH_UNITS_PER_M * (turn @ pos[0] + shift), euler.ravel()])

    def _row(self, message: dict) -> str:
        mine = [b for b in message.get("bodies") or [] if b.get("id") == self.body_id]
        pose = mine[0].get("pose") if mine else None
        to_bvh = bvh_transform(message)
        self.floor_known |= not np.array_equal(to_bvh, bvh_transform(None))
        if pose is not None:
            try:
                pose = np.asarray(pose, dtype=np.float64)
                row = _numbers(self.channels(pose, to_bvh))
            except (ShapeError, ValueError):  # a malformed pose counts as none
                pose = None
            else:
                self._keep(pose, to_bvh)
                return row
        self._keep(None, to_bvh)
        return self._pose_row(None, to_bvh)

    def _written_rows(self) -> list[str]:
        """The MOTION rows written so far, read back from the file."""
        self._flush()
        try:
            text = self.path.read_bytes().decode("ascii")
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
        return text.split("\nFrame Time:", 1)[1].split("\n")[1:-1] if self.frames else []

    def _keep(self, pose: np.ndarray | None, to_bvh: np.ndarray) -> None:
        """Remember the pose of the row being written while the body may still change (rows
        without a pose cost a reference each; up to :data:`KEPT_POSES` rows with one)."""
        if self._poses is None or self._kept_posed >= KEPT_POSES:
            return
        if self._poses and np.array_equal(self._poses[-1][1], to_bvh):
            to_bvh = self._poses[-1][1]  # the same transform, shared
        self._poses.append((None if pose is None else pose.astype(np.float32), to_bvh))
        self._kept_posed += pose is not None

    def _pose_row(self, pose: np.ndarray | None, to_bvh: np.ndarray) -> str:
        """The row of ``pose`` (None: no pose in that frame: the last row, or before any the rest pose)."""
        if pose is not None:
            return _numbers(self.channels(pose, to_bvh))
        if self._last is None:
            if np.array_equal(to_bvh, bvh_transform(None)):
                rest = self.body.rest_pose(quaternion=UPRIGHT)
            else:  # the world frame is known: stand on its floor at its origin
                rest, to_bvh = self.body.rest_pose(translation=(0.0, self.body.floor_offset, 0.0)), np.eye(4)
            self._last = _numbers(self.channels(rest, to_bvh))
        return self._last

    def close(self) -> None:
        """Close the file; a warning when its motion was never placed on a floor."""
        warn = not self._closed and self.frames > 0 and not self.floor_known
        super().close()
        if warn:
            log.warning("%s: no floor was known (none visible to fit, or --floor off): the motion is in the "
                        "camera's axes turned upright, not standing on a floor; pass --floor EXTRINSICS.json "
                        "to place it", self.path)

    def frame(self, message: dict, frame: Frame | None = None) -> None:
        """Append one MOTION row for ``message`` and rewrite the ``Frames:`` count."""
        self._check_open()
        row = self._row(message)
        try:
            self._file.write((row + "\n").encode("ascii"))
            self._file.seek(self._count_at)
            self._file.write(f"{self.frames + 1:<{FRAMES_WIDTH}d}".encode("ascii"))
            self._file.seek(0, 2)
        except OSError as exc:
            raise write_error(self.what, self.path, exc) from exc
        self._flush()
        self._last = row
        self.frames += 1


def bvh_transform(message: dict | None) -> np.ndarray:
    """The (4, 4) transform from a frame message's coordinates to the BVH world: identity for
    world ``coordinates``, the message's ``camera_to_world`` for camera coordinates where it is
    known (and rigid), else :data:`CAMERA_TO_BVH` (None: that one)."""
    out = np.eye(4)
    if message is not None and message.get("coordinates") == "world":
        return out
    given = None if message is None else message.get("camera_to_world")
    if given is not None:
        try:
            return check_rigid(given, "camera_to_world")
        except ConfigError:  # a malformed transform counts as none
            pass
    out[:3, :3] = CAMERA_TO_BVH
    return out


class PerIdBvhSink:
    """One :class:`BvhSink` per body id in folder ``out_dir``, all animating ``body`` at ``fps``;
    with ``body_of`` (``--personalize``), each id's file animates the body that id is tracked
    with, and is rewritten with the new skeleton when that body changes (its shape locked).

    Id 0's file, ``poses.bvh``, is created at once and has a row for every frame message (as
    a run of one person always had); id N's, ``poses_id<N>.bvh``, is created by the first
    message that holds a body with id N and has a row for that message and every later one.
    Each file repeats its last row on frames where its id is absent or has no pose, and is a
    complete BVH after every frame. Every id seen keeps its file open and gets a row per
    frame until :meth:`close`. A body whose id is not an integer >= 0 raises
    :class:`~swarmpose.core.errors.OutputError`, as does a file that cannot be written.
    """

    what = "the BVH files"

    def __init__(self, out_dir: str | Path, body: SkinnedBody, fps: float = 30.0, body_of: BodyOf | None = None
                 ) -> None:
        self.out_dir = Path(out_dir)
        self.body = body
        self.fps = fps
        self.body_of = body_of
        self.frames = 0
        self._closed = False
        self.sinks: dict[int, BvhSink] = {0: self._open(0)}

    def _open(self, body_id: int) -> BvhSink:
        body = (self.body_of(body_id) if self.body_of is not None else None) or self.body
        return BvhSink(bvh_path(self.out_dir, body_id), body, self.fps, body_id, may_change=self.body_of is not None)

    @property
    def path(self) -> Path:
        """``poses.bvh``, the file of id 0."""
        return self.sinks[0].path

    @property
    def paths(self) -> list[Path]:
        """Every BVH file created so far, by id."""
        return [self.sinks[k].path for k in sorted(self.sinks)]

    def frame(self, message: dict, frame: Frame | None = None) -> None:
        """Open the files of ids first seen in ``message``, then append one row to every file."""
        if self._closed:
            raise OutputError(f"{self.what} in {self.out_dir} are closed; open a new sink to write more frames")
        for body in message.get("bodies") or []:
            body_id = _check_id(body.get("id"), f"frame {message.get('frame', '?')}")
            if body_id not in self.sinks:
                self.sinks[body_id] = self._open(body_id)
        for body_id, sink in self.sinks.items():
            body = self.body_of(body_id) if self.body_of is not None else None
            if body is not None:
                sink.use_body(body)
            sink.frame(message, frame)
        self.frames += 1

    def status(self, message: dict) -> None:
        """Status messages are not recorded."""

    def close(self) -> None:
        """Close every file (idempotent); the first error, if any, is raised after all are closed."""
        if self._closed:
            return
        self._closed = True
        error: OutputError | None = None
        for sink in self.sinks.values():
            try:
                sink.close()
            except OutputError as exc:
                error = error or exc
        if error is not None:
            raise error
