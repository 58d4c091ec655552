"""What tracking a frame gives: :class:`BodyResult` per person, :class:`FrameResult` per frame.

Both turn into the protocol's messages (``to_message``), so a result seen through the
Python API, written to ``poses.jsonl`` or published over zenoh is the same thing.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from swarmpose.body.joint_set import SKELETON_NAMES, posed_joints
from swarmpose.body.kinematics import matrix_to_quaternion, to_xyzw
from swarmpose.body.skeleton import EVAL_JOINTS
from swarmpose.body.skinned import SkinnedBody
from swarmpose.core.camera import Intrinsics
from swarmpose.core.world import WorldState, transform_points, transform_poses
from swarmpose.detect.joints import Joints2D
from swarmpose.messages.build import body_message, frame_message, full_joint_arrays

STATES = ("init", "tracking", "lost")


@dataclass(frozen=True)
class Joint:
    """One joint of one body: ``position_m`` (3,) camera frame m and ``pixel`` (2,) px, each
    None where unknown; ``confidence`` 0..1; ``orientation_xyzw`` (4,) the unit quaternion of the
    joint's frame in the camera frame (:mod:`swarmpose.body.joint_set`), None without a pose."""

    position_m: np.ndarray | None
    pixel: np.ndarray | None
    confidence: float
    orientation_xyzw: np.ndarray | None = None


@dataclass(frozen=True)
class PosedSkeleton:
    """The full joint set (:data:`~swarmpose.body.joint_set.SKELETON_NAMES`, K = 28) of a posed
    body: ``positions`` (K, 3) m and ``frames`` (K, 3, 3) (each joint's axes as columns) in the
    camera frame, ``pixels`` (K, 2) px (NaN behind the camera)."""

    positions: np.ndarray
    frames: np.ndarray
    pixels: np.ndarray


def posed_skeleton(body: SkinnedBody, pose: np.ndarray, intrinsics: Intrinsics,
                   transforms: np.ndarray | None = None) -> PosedSkeleton:
    """The full joint set of ``body`` at ``pose`` (36,), camera frame, projected with ``intrinsics``;
    ``transforms`` (1, B, 3, 4): the pose's bone transforms where the caller has them."""
    positions, frames = posed_joints(body, pose, transforms)
    return PosedSkeleton(positions[0], frames[0], intrinsics.project(positions[0]))


@dataclass(frozen=True)
class BodyResult:
    """One tracked person in one frame.

    id: track id; state: init | tracking | lost; reason: why (empty when tracking
    normally); pose: (36,) or None; joints3d: (14, 3) m, camera frame, in ``EVAL_JOINTS``
    order (NaN where unknown); joints2d: (14, 2) px; confidence: (14,) 0..1; objective: E
    and its terms of the chosen pose; timings_ms: where this body's time went; detection:
    the 2D joints it was fitted to (None: none); unfiltered: with ``--smoothing``, the result
    as the search found it, before the published pose was filtered (None: not filtered);
    velocities: (14, 3) m/s of the joints, camera frame (None: not estimated); skeleton: the
    full joint set of the pose with orientations (None: no pose, or not computed).
    """

    id: int
    state: str
    reason: str
    pose: np.ndarray | None
    joints3d: np.ndarray
    joints2d: np.ndarray
    confidence: np.ndarray
    objective: Mapping[str, float] = field(default_factory=dict)
    timings_ms: Mapping[str, float] = field(default_factory=dict)
    detection: Joints2D | None = None
    unfiltered: BodyResult | None = None
    velocities: np.ndarray | None = None
    skeleton: PosedSkeleton | None = None

    @property
    def found(self) -> BodyResult:
        """The result as the search found it (itself unless the published pose is filtered): what the
        tracking's own feedback (the detector's next box, association, personalisation) uses."""
        return self if self.unfiltered is None else self.unfiltered

    @property
    def joints(self) -> dict[str, Joint]:
        """The full joint set by name (``pelvis``, ``left_wrist``, ...; ``SKELETON_NAMES`` order), in
        the camera frame: each joint as the frame message has it, unrounded."""
        arrays = full_joint_arrays(self.joints3d, self.joints2d, self.confidence, self.skeleton_values())

        def known(v: np.ndarray) -> np.ndarray | None:
            return v.copy() if np.all(np.isfinite(v)) else None
        return {name: Joint(known(p3), known(p2), float(c), known(q))
                for name, p3, p2, c, q in zip(SKELETON_NAMES, *arrays)}

    def skeleton_values(self, camera_to_world: np.ndarray | None = None) -> tuple[np.ndarray, ...] | None:
        """The full set's positions (K, 3) m, pixels (K, 2) px and orientations (K, 4) xyzw, in the
        camera frame or, with ``camera_to_world`` (4, 4), the world's; None without a skeleton."""
        if self.skeleton is None:
            return None
        positions, frames = self.skeleton.positions, self.skeleton.frames
        if camera_to_world is not None:
            positions = transform_points(camera_to_world, positions)
            frames = np.asarray(camera_to_world)[:3, :3] @ frames
        return positions, self.skeleton.pixels, to_xyzw(matrix_to_quaternion(frames))

    def joints_box(self) -> np.ndarray | None:
        """(4,) [u0, v0, u1, v1] px around the finite 2D joints (where to detect next), or None."""
        joints2d = self.found.joints2d
        ok = np.all(np.isfinite(joints2d), axis=1)
        if not ok.any():
            return None
        pts = joints2d[ok]
        return np.concatenate([pts.min(axis=0), pts.max(axis=0)])

    def to_message(self, camera_to_world: np.ndarray | None = None) -> dict:
        """This body as one entry of a frame message's ``bodies``; with ``camera_to_world`` (4, 4),
        its joints and pose in that world frame (pixels stay pixels)."""
        detection = None
        if self.detection is not None:
            detection = {"layout": self.detection.layout.name, "keypoints": self.detection.as_dict()}
        joints3d, pose, velocities = self.joints3d, self.pose, self.velocities
        if camera_to_world is not None:
            joints3d = transform_points(camera_to_world, joints3d)
            pose = None if pose is None else transform_poses(camera_to_world, pose)
            velocities = None if velocities is None else velocities @ np.asarray(camera_to_world)[:3, :3].T
        return body_message(self.id, self.state, self.reason, pose, joints3d, self.joints2d,
                            self.confidence, self.objective, detection, velocities,
                            self.skeleton_values(camera_to_world))


def lost_body(reason: str, body_id: int = 0, timings_ms: Mapping[str, float] | None = None,
              detection: Joints2D | None = None) -> BodyResult:
    """A body with no estimate (state lost), why, and the detection it was lost with (if any)."""
    n = len(EVAL_JOINTS)
    return BodyResult(body_id, "lost", reason, None, np.full((n, 3), np.nan), np.full((n, 2), np.nan),
                      np.zeros(n), {}, dict(timings_ms or {}), detection)


@dataclass(frozen=True)
class FrameResult:
    """Everything about one frame of a source.

    index / timestamp_ns: the source's frame number and capture time; bodies: the tracked
    people (empty when the frame was skipped or failed); reason: why there are no bodies
    (skipped frame, detector or tracker failure; empty otherwise); timings_ms: detection and
    tracking time; skipped: the source could not deliver the frame; received_ns: wall-clock
    time (ns) the frame was taken from the source (latency counts from there); people: with
    several people, the counts a status reports (``tracked``, ``found``, ``created``,
    ``retired``, ``beyond_max_people``, ``no_person``), None in single-person mode; world: the
    camera's floor and camera-to-world transform as known at this frame (None: no floor, or
    none asked for); coordinates: the frame wanted in the message, ``camera`` or ``world``
    (world takes effect once ``world.camera_to_world`` is known).
    """

    index: int
    timestamp_ns: int
    bodies: tuple[BodyResult, ...] = ()
    reason: str = ""
    timings_ms: Mapping[str, float] = field(default_factory=dict)
    skipped: bool = False
    received_ns: int = 0
    people: Mapping[str, int] | None = None
    world: WorldState | None = None
    coordinates: str = "camera"

    @property
    def state(self) -> str:
        """``skipped``, the first body's state, or ``lost`` (no body)."""
        if self.skipped:
            return "skipped"
        return self.bodies[0].state if self.bodies else "lost"

    def to_message(self, camera: str = "camera0", *, received_ns: int | None = None,
                   publish_ns: int | None = None) -> dict:
        """The protocol's ``swarmpose.frame`` message of this frame (``protocol/frame.schema.json``).
        publish_ns: now unless given; received_ns: this result's (or publish time when unknown)."""
        publish = time.time_ns() if publish_ns is None else int(publish_ns)
        received = received_ns if received_ns is not None else (self.received_ns or publish)
        transform = None if self.world is None else self.world.camera_to_world
        in_world = self.coordinates == "world" and transform is not None
        bodies = [b.to_message(transform if in_world else None) for b in self.bodies]
        return frame_message(camera, self.index, self.timestamp_ns, received, publish, bodies, reason=self.reason,
                             timings_ms=self.timings_ms, coordinates="world" if in_world else "camera",
                             camera_to_world=transform)
