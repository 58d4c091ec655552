"""One frame rendered from a known pose, and one tracked step from a given track: the scaffolding
of the proposals' tests (depth flips, limb exchanges, arm proposals)."""

from __future__ import annotations

import numpy as np

from swarmpose.body.skeleton import COCO17
from swarmpose.core.camera import Intrinsics
from swarmpose.detect.joints import Joints2D
from swarmpose.sim.render import Renderer, Room
from swarmpose.sources.base import Frame
from swarmpose.tracking.body_tracker import BodyTracker
from swarmpose.tracking.config import TrackerConfig

ROOM = Room(floor_point=np.array([0.0, 1.0, 0.0]), floor_normal=np.array([0.0, -1.0, 0.0]),
            wall_point=np.array([0.0, 0.0, 4.5]), wall_normal=np.array([0.0, 0.0, -1.0]))
"""A floor 1 m below the camera and a wall 4.5 m in front of it (camera frame, m)."""


def room_depth(body, pose: np.ndarray, intr: Intrinsics) -> np.ndarray:
    """(H, W) float32 m: the depth of ``body`` posed as ``pose`` (36,) in :data:`ROOM`."""
    return Renderer(intr).render(body.pose(pose[None])[0], body.triangles, ROOM)[0].astype(np.float32)


def detection_of(body, pose: np.ndarray, intr: Intrinsics, scores: np.ndarray | None = None) -> Joints2D:
    """The COCO-17 keypoints of ``pose`` (36,) projected exactly, scored 1 (or ``scores``, (17,))."""
    keypoints = intr.project(body.posed_points(pose[None], COCO17.points)[0])
    scores = np.ones(len(keypoints)) if scores is None else scores
    return Joints2D(COCO17, np.column_stack([keypoints, scores]), 1, 0)


def step_from(body, intr: Intrinsics, track: np.ndarray, depth: np.ndarray, detection: Joints2D,
              config: TrackerConfig) -> np.ndarray:
    """The pose (36,) one tracked frame finds when the track (10 frames old) holds ``track`` (36,)."""
    tracker = BodyTracker(body, intr, config)
    tracker.previous, tracker.age = track.copy(), 10
    tracker.history.restart(track.copy())
    return tracker.step(Frame(1, 33_333_333, depth, None, intr), detection).found.pose
