"""Retargeting every motion-capture clip of the assets onto the MakeHuman body.

Oracle: the clip's own joint positions (BVH forward kinematics). Rotation-invariant
interior angles (elbow, knee, upper arm vs torso, thigh vs torso) of the retargeted body
must match those of the clip, and the body's bones keep their lengths.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MAKEHUMAN, MOCAP, mocap_param, needs_assets

from swarmpose.core.errors import MotionError

pytestmark = needs_assets

CLIPS = [mocap_param(p) for p in sorted(MOCAP.glob("*.bvh"))] if MOCAP.is_dir() else []
POINTS = ["left_shoulder", "left_elbow", "left_wrist", "left_hip", "left_knee", "left_ankle", "neck", "mid_hip",
          "right_shoulder", "right_elbow", "right_wrist", "right_hip", "right_knee", "right_ankle"]


@pytest.fixture(scope="module")
def body():
    from swarmpose.body.makehuman import load_makehuman
    return load_makehuman(str(MAKEHUMAN), "male")


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, -1), -1, 1)))


def _interior_angles(p) -> np.ndarray:
    """(N, 8) elbow, knee, arm-torso and thigh-torso angles (deg) from a point getter."""
    out = []
    torso = p("neck") - p("pelvis")
    for s in ("left", "right"):
        out += [_angle(p(f"{s}_shoulder") - p(f"{s}_elbow"), p(f"{s}_wrist") - p(f"{s}_elbow")),
                _angle(p(f"{s}_hip") - p(f"{s}_knee"), p(f"{s}_ankle") - p(f"{s}_knee")),
                _angle(p(f"{s}_elbow") - p(f"{s}_shoulder"), torso),
                _angle(p(f"{s}_knee") - p(f"{s}_hip"), torso)]
    return np.stack(out, -1)


@pytest.mark.parametrize("clip_name", CLIPS)
def test_clip_retargets_with_matching_joint_angles(body, clip_name):
    from swarmpose.body.kinematics import matrix_to_quaternion
    from swarmpose.motion.bvh import read_bvh
    from swarmpose.motion.retarget import read_clip, retarget

    clip = read_bvh(clip_name).resample(30.0)
    motion = retarget(clip, body)
    assert len(motion) == len(clip) and motion.within_limits()
    assert np.all(np.isfinite(motion.angles)) and np.all(np.isfinite(motion.root_offset))
    h = np.zeros((len(motion), 36))
    h[:, :3], h[:, 3:7], h[:, 7:] = motion.root_offset, matrix_to_quaternion(motion.root_rotation), motion.angles
    posed = dict(zip(POINTS, np.moveaxis(body.posed_points(h, POINTS), 1, 0)))

    def body_point(role: str) -> np.ndarray:
        return posed["mid_hip" if role == "pelvis" else role]

    idx = read_clip(clip).roles.index
    _, positions = clip.global_transforms()
    clip_angles = _interior_angles(lambda role: positions[:, idx[role]])
    body_angles = _interior_angles(body_point)
    error = np.median(np.abs(clip_angles - body_angles), axis=0)
    assert np.all(error < 15.0), dict(zip(["elbow", "knee", "arm", "thigh"] * 2, error.round(1)))
    # Bones keep the body's lengths (retargeting moves joints by rotations only).
    upper = np.linalg.norm(posed["left_elbow"] - posed["left_shoulder"], axis=1)
    np.testing.assert_allclose(upper, np.linalg.norm(body.point("left_elbow") - body.point("left_shoulder")), rtol=1e-9)


def test_resampling_sets_the_motion_rate(body):
    from swarmpose.motion.retarget import load_motion
    motion = load_motion(str(MOCAP / "bvh11_131_01.bvh"), body, fps=15.0)
    assert motion.fps == 15.0
    assert abs(motion.duration - 994 / 120) < 0.2


def test_walking_clip_moves_forward_and_stays_upright(body):
    from swarmpose.motion.retarget import load_motion
    motion = load_motion(str(MOCAP / "bvh11_131_01.bvh"), body, fps=30.0)  # start, walk, stop
    up = motion.root_rotation[:, :, 1]  # the body's up axis in the world
    assert np.all(up[:, 1] > 0.9)
    travel = motion.root_offset[-1] - motion.root_offset[0]
    assert np.hypot(travel[0], travel[2]) > 1.0  # walks more than a metre
    assert abs(travel[1]) < 0.1


def test_unknown_skeleton_is_a_clear_error(tmp_path, body):
    from swarmpose.motion.retarget import load_motion
    bvh = tmp_path / "robot.bvh"
    bvh.write_text("HIERARCHY\nROOT Base\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
                   "Zrotation Xrotation Yrotation\n JOINT Arm\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation "
                   "Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 1\n"
                   "Frame Time: 0.0333\n0 0 0 0 0 0 0 0 0\n")
    with pytest.raises(MotionError, match="unknown BVH skeleton"):
        load_motion(str(bvh), body)
