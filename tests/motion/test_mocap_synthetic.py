"""Retargeting a small hand-written CMU-named BVH (runs without the shared assets).

The clip's joints give the oracle: interior angles (elbow, knee) of the retargeted
built-in body must equal those of the clip, and feet that end in End Sites work.
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmpose.motion.bvh import read_bvh
from swarmpose.motion.retarget import retarget


def _joint(name: str, offset, children: str = "", end=None) -> str:
    inner = children or f"End Site\n{{\nOFFSET {end[0]} {end[1]} {end[2]}\n}}\n"
    return (f"JOINT {name}\n{{\nOFFSET {offset[0]} {offset[1]} {offset[2]}\n"
            f"CHANNELS 3 Zrotation Xrotation Yrotation\n{inner}}}\n")


def _skeleton() -> tuple[str, list[str]]:
    """A T-pose CMU MotionBuilder skeleton in centimetres, Y up, facing +Z; joint order."""
    j = _joint

    legs = ""
    for s, x in (("Left", 1), ("Right", -1)):
        legs += j(f"{s[0]}HipJoint", (x * 10, -5, 0),
                  j(f"{s}UpLeg", (0, 0, 0), j(f"{s}Leg", (0, -43, 0), j(f"{s}Foot", (0, -43, 0), end=(0, -6, 15)))))
    arms = ""
    for s, x in (("Left", 1), ("Right", -1)):
        arms += j(f"{s}Shoulder", (x * 3, 0, 0),
                  j(f"{s}Arm", (x * 15, 0, 0), j(f"{s}ForeArm", (x * 30, 0, 0),
                                                j(f"{s}Hand", (x * 25, 0, 0), end=(x * 8, 0, 0)))))
    spine = j("LowerBack", (0, 5, 0), j("Spine", (0, 15, 0), j("Spine1", (0, 15, 0),
              j("Neck", (0, 15, 0), j("Neck1", (0, 5, 0), j("Head", (0, 5, 0), end=(0, 15, 0)))) + arms)))
    text = ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            f"Yrotation\n{legs}{spine}}}\n")
    order = [line.split()[1] for line in text.splitlines() if line.startswith(("ROOT", "JOINT"))]
    return text, order


@pytest.fixture(scope="module")
def body():
    from swarmpose.body.parametric import build_parametric_body
    return build_parametric_body()


def test_elbow_and_knee_angles_transfer_and_end_site_feet_work(tmp_path, body):
    text, order = _skeleton()
    frames = np.zeros((3, 3 + 3 * len(order)))
    frames[:, 1] = 95.0
    frames[:, 5] = 30.0  # the whole clip turned 30 degrees about the vertical: frame 0 is not the zero pose
    col = {name: 3 + 3 * i for i, name in enumerate(order)}
    frames[1, col["LeftForeArm"] + 2] = -90.0  # Yrotation: forearm swings forward (towards +Z)
    frames[2, col["RightLeg"] + 1] = 60.0  # Xrotation: the shin swings back (knee flexion)
    bvh = tmp_path / "tiny.bvh"
    bvh.write_text(text + "MOTION\nFrames: 3\nFrame Time: 0.0333333\n"
                   + "\n".join(" ".join(f"{v:.4f}" for v in row) for row in frames) + "\n")
    clip = read_bvh(bvh)
    motion = retarget(clip, body)
    assert motion.within_limits()
    h = np.zeros((3, 36))
    from swarmpose.body.kinematics import matrix_to_quaternion
    h[:, 3:7], h[:, 7:], h[:, :3] = matrix_to_quaternion(motion.root_rotation), motion.angles, motion.root_offset
    names = ["left_shoulder", "left_elbow", "left_wrist", "right_hip", "right_knee", "right_ankle"]
    p = dict(zip(names, np.moveaxis(body.posed_points(h, names), 1, 0)))

    def interior(a, b, c):
        u, v = p[a] - p[b], p[c] - p[b]
        return np.degrees(np.arccos(np.sum(u * v, -1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)))

    elbow = interior("left_shoulder", "left_elbow", "left_wrist")
    knee = interior("right_hip", "right_knee", "right_ankle")
    assert elbow[0] == pytest.approx(180, abs=3) and elbow[1] == pytest.approx(90, abs=3)
    assert knee[0] == pytest.approx(180, abs=3) and knee[2] == pytest.approx(120, abs=3)
    assert p["left_wrist"][1, 2] > p["left_elbow"][1, 2] + 0.15  # flexed forward, not backward
    # The clip stands with flat feet (End Sites ahead and below the ankles): ankle pitch 0.
    from swarmpose.body.skeleton import ANGLE_NAMES
    for angle in ("left_ankle.pitch", "left_ankle.yaw", "right_ankle.pitch", "right_ankle.yaw"):
        np.testing.assert_allclose(motion.angles[0, ANGLE_NAMES.index(angle)], 0.0, atol=1e-6)
