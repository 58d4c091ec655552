"""The BVH reader against hand-computed oracles, malformed files and the real mocap assets."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import MOCAP, mocap_param

from swarmpose.core.errors import MotionError
from swarmpose.motion.bvh import BvhClip, read_bvh, slerp

# Elementary 90-degree rotations, written out by hand (column vectors, right-handed).
RX90 = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)
RY90 = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=float)
RZ90 = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)

TINY = """HIERARCHY
ROOT Hips
{
\tOFFSET 0.0 0.0 0.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT Spine
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Xrotation Yrotation Zrotation
\t\tJOINT Head
\t\t{
\t\t\tOFFSET 0 5 0
\t\t\tCHANNELS 3 Yrotation Xrotation Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0 2 0
\t\t\t}
\t\t}
\t}
    JOINT Leg
    {
        OFFSET 3 0 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        End Site
        {
            OFFSET 0 -8 0
        }
    }
}
MOTION
Frames: 2
Frame Time:\t0.5
0 0 0  0 0 0  0 0 0  0 0 0  0 0 0
1 2 3  90 0 0  90 0 0  0 0 0  0 0 0


"""


def write(tmp_path: Path, text: str, name: str = "clip.bvh", newline: str = "\n") -> Path:
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def two_joint(channels: str, values: str, root_offset: str = "4 5 6") -> str:
    """A root without position channels (``channels`` only) and a child 1 unit up."""
    n = len(channels.split())
    return (f"HIERARCHY\nROOT A\n{{\n OFFSET {root_offset}\n CHANNELS {n} {channels}\n JOINT B\n {{\n"
            "  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n"
            f" }}\n}}\nMOTION\nFrames: 1\nFrame Time: 0.0333333\n{values} 0 0 0\n")


# ---------------------------------------------------------------------------- structure and FK
@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_tiny_clip_structure(tmp_path, newline):
    clip = read_bvh(write(tmp_path, TINY, newline=newline))
    assert isinstance(clip, BvhClip)
    assert clip.name == "clip"
    assert clip.joint_names == ("Hips", "Spine", "Head", "Leg")
    assert clip.parents.tolist() == [-1, 0, 1, 0]
    np.testing.assert_array_equal(clip.offsets, [[0, 0, 0], [0, 10, 0], [0, 5, 0], [3, 0, 0]])
    assert set(clip.end_offsets) == {2, 3}
    np.testing.assert_array_equal(clip.end_offsets[2], [0, 2, 0])
    np.testing.assert_array_equal(clip.end_offsets[3], [0, -8, 0])
    assert clip.frame_time == 0.5 and clip.fps == 2.0 and len(clip) == 2
    assert clip.local_rotations.shape == (2, 4, 3, 3)
    assert clip.local_translations is None
    np.testing.assert_array_equal(clip.root_positions, [[0, 0, 0], [1, 2, 3]])
    assert clip.joint_index("Head") == 2
    with pytest.raises(MotionError, match="no joint named 'Neck'"):
        clip.joint_index("Neck")


def test_tiny_clip_forward_kinematics_by_hand(tmp_path):
    clip = read_bvh(write(tmp_path, TINY))
    rot, pos = clip.global_transforms()
    # Frame 0: all rotations zero -> accumulated offsets.
    np.testing.assert_allclose(pos[0], [[0, 0, 0], [0, 10, 0], [0, 15, 0], [3, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(rot[0], np.broadcast_to(np.eye(3), (4, 3, 3)), atol=1e-12)
    # Frame 1: root at (1, 2, 3) turned 90 deg about Z; Spine 90 deg about X.
    #   Spine = (1,2,3) + Rz90 (0,10,0) = (1,2,3) + (-10,0,0)        = (-9, 2, 3)
    #   Head  = Spine + Rz90 Rx90 (0,5,0) = Spine + Rz90 (0,0,5)     = (-9, 2, 8)
    #   Leg   = (1,2,3) + Rz90 (3,0,0)     = (1,2,3) + (0,3,0)       = (1, 5, 3)
    np.testing.assert_allclose(pos[1], [[1, 2, 3], [-9, 2, 3], [-9, 2, 8], [1, 5, 3]], atol=1e-9)
    np.testing.assert_allclose(rot[1, 0], RZ90, atol=1e-12)
    np.testing.assert_allclose(rot[1, 1], RZ90 @ RX90, atol=1e-12)
    np.testing.assert_allclose(rot[1, 2], RZ90 @ RX90, atol=1e-12)
    np.testing.assert_allclose(clip.rest_positions(), pos[0], atol=1e-12)


@pytest.mark.parametrize(("channels", "values", "matrix", "child"), [
    # R = R_first @ R_second (intrinsic). Child offset (0, 1, 0) from root offset (4, 5, 6).
    ("Zrotation Xrotation Yrotation", "90 90 0", RZ90 @ RX90, (0, 0, 1)),  # Rx: y->z, Rz keeps z
    ("Xrotation Zrotation Yrotation", "90 90 0", RX90 @ RZ90, (-1, 0, 0)),  # Rz: y->-x, Rx keeps x
    ("Yrotation Xrotation Zrotation", "90 90 0", RY90 @ RX90, (1, 0, 0)),  # Rx: y->z, Ry: z->x
    ("Xrotation Yrotation Zrotation", "90 90 0", RX90 @ RY90, (0, 0, 1)),  # Ry keeps y, Rx: y->z
    ("Zrotation Yrotation Xrotation", "0 90 90", RY90 @ RX90, (1, 0, 0)),
])
def test_channel_order_is_intrinsic(tmp_path, channels, values, matrix, child):
    clip = read_bvh(write(tmp_path, two_joint(channels, values)))
    np.testing.assert_allclose(clip.local_rotations[0, 0], matrix, atol=1e-12)
    np.testing.assert_allclose(clip.root_positions[0], [4, 5, 6])  # no position channels: the offset
    _, pos = clip.global_transforms()
    np.testing.assert_allclose(pos[0, 1], np.array([4, 5, 6]) + child, atol=1e-12)


def test_general_angles_match_elementary_product(tmp_path):
    clip = read_bvh(write(tmp_path, two_joint("Yrotation Zrotation Xrotation", "30 -45 60")))
    a, b, c = np.radians([30, -45, 60])
    ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    rz = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(c), -np.sin(c)], [0, np.sin(c), np.cos(c)]])
    np.testing.assert_allclose(clip.local_rotations[0, 0], ry @ rz @ rx, atol=1e-12)


def test_position_channels_on_child_replace_its_offset(tmp_path):
    text = ("HIERARCHY\nROOT R\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation "
            "Xrotation\n JOINT C\n {\n  OFFSET 0 1 0\n  CHANNELS 6 Zrotation Xposition Yposition Zposition Yrotation "
            "Xrotation\n  End Site\n  {\n   OFFSET 1 0 0\n  }\n }\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n"
            "0 0 0 0 0 0 0 0 1 0 0 0\n"
            "1 1 1 90 0 0 0 7 8 9 0 0\n")
    clip = read_bvh(write(tmp_path, text))
    assert clip.local_translations is not None and clip.local_translations.shape == (2, 2, 3)
    np.testing.assert_array_equal(clip.local_translations[:, 1], [[0, 1, 0], [7, 8, 9]])
    np.testing.assert_array_equal(clip.local_translations[:, 0], clip.root_positions)
    _, pos = clip.global_transforms()
    # C = (1,1,1) + Rz90 (7,8,9) = (1,1,1) + (-8,7,9)
    np.testing.assert_allclose(pos[1, 1], [-7, 8, 10], atol=1e-12)
    np.testing.assert_allclose(pos[0, 1], [0, 1, 0], atol=1e-12)


def test_position_channels_holding_positions_in_the_roots_frame_become_offsets(tmp_path):
    """CMU ASF conversions write where a joint is (the root's frame), not its offset: forward
    kinematics must put it there. Hand-computed: the child is 1 unit up the root's turned Y axis
    (frame 2: 1.1, a bone stretched)."""
    text = ("HIERARCHY\nROOT R\n{\n OFFSET 0 0 0\n CHANNELS 4 Xposition Yposition Zposition Zrotation\n JOINT C\n"
            " {\n  OFFSET 0 1 0\n  CHANNELS 3 Xposition Yposition Zposition\n  End Site\n  {\n   OFFSET 1 0 0\n  }\n"
            " }\n}\nMOTION\nFrames: 3\nFrame Time: 0.1\n"
            "0 0 0 0  0 1 0\n"
            "10 0 0 90  9 0 0\n"
            "5 5 5 0  5 6.1 5\n")
    clip = read_bvh(write(tmp_path, text))
    np.testing.assert_allclose(clip.local_translations[:, 1], [[0, 1, 0], [0, 1, 0], [0, 1.1, 0]], atol=1e-12)
    _, pos = clip.global_transforms()
    np.testing.assert_allclose(pos[:, 1], [[0, 1, 0], [9, 0, 0], [5, 6.1, 5]], atol=1e-12)


# ---------------------------------------------------------------------------- resampling
def _yaw_clip(tmp_path, degrees, xs, frame_time: float = 0.1) -> BvhClip:
    lines = "".join(f"{x} 0 0 {d} 0 0\n" for d, x in zip(degrees, xs, strict=True))
    text = ("HIERARCHY\nROOT R\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation "
            "Zrotation\n End Site\n {\n  OFFSET 0 0 1\n }\n}\n"
            f"MOTION\nFrames: {len(degrees)}\nFrame Time: {frame_time}\n{lines}")
    return read_bvh(write(tmp_path, text))


def _ry(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def test_resample_linear_rotation_midpoints(tmp_path):
    clip = _yaw_clip(tmp_path, [0, 20, 40, 60, 80], [0, 1, 2, 3, 4])  # 10 fps, 0.4 s
    up = clip.resample(20.0)
    assert len(up) == 9 and up.fps == pytest.approx(20.0)
    for k in range(9):
        np.testing.assert_allclose(up.local_rotations[k, 0], _ry(10.0 * k), atol=1e-9)
        np.testing.assert_allclose(up.root_positions[k], [0.5 * k, 0, 0], atol=1e-9)
    odd = clip.resample(25.0)  # samples at 0, 0.04, ..., 0.4 s
    assert len(odd) == 11
    np.testing.assert_allclose(odd.local_rotations[3, 0], _ry(24.0), atol=1e-9)
    np.testing.assert_allclose(odd.root_positions[3], [1.2, 0, 0], atol=1e-9)
    down = clip.resample(5.0)
    assert len(down) == 3
    np.testing.assert_allclose(down.local_rotations[:, 0], [_ry(0), _ry(40), _ry(80)], atol=1e-9)


def test_resample_is_spherical_not_linear(tmp_path):
    clip = _yaw_clip(tmp_path, [0, 170], [0, 0], frame_time=1.0)
    mid = clip.resample(2.0).local_rotations[1, 0]
    np.testing.assert_allclose(mid, _ry(85.0), atol=1e-9)  # a matrix lerp would not be a rotation
    # Across the +-180 seam slerp takes the short way: 170 -> -170 passes 180.
    seam = _yaw_clip(tmp_path, [170, -170], [0, 0], frame_time=1.0).resample(2.0).local_rotations[1, 0]
    np.testing.assert_allclose(seam, _ry(180.0), atol=1e-9)


def test_resample_keeps_hierarchy_and_structure(tmp_path):
    clip = read_bvh(write(tmp_path, TINY))
    up = clip.resample(4.0)  # 0.5 s at 4 fps -> 3 frames
    assert len(up) == 3 and up.joint_names == clip.joint_names
    np.testing.assert_allclose(up.local_rotations[[0, 2]], clip.local_rotations, atol=1e-12)
    np.testing.assert_allclose(up.root_positions[1], [0.5, 1, 1.5])
    np.testing.assert_allclose(up.local_rotations[1, 0], [[np.sqrt(0.5), -np.sqrt(0.5), 0],
                                                          [np.sqrt(0.5), np.sqrt(0.5), 0], [0, 0, 1]], atol=1e-12)
    with pytest.raises(MotionError):
        clip.resample(0.0)


def test_slerp_endpoints_and_sign():
    q0 = np.array([1.0, 0, 0, 0])
    q1 = -np.array([np.cos(0.5), 0, np.sin(0.5), 0])  # same rotation as its negation
    np.testing.assert_allclose(slerp(q0, q1, 0.0), q0, atol=1e-12)
    np.testing.assert_allclose(np.abs(slerp(q0, q1, 1.0)), np.abs(q1), atol=1e-12)
    np.testing.assert_allclose(slerp(q0, q1, 0.5), [np.cos(0.25), 0, np.sin(0.25), 0], atol=1e-12)


# ---------------------------------------------------------------------------- malformed files
def _one_line_error(path: Path, fn=read_bvh) -> str:
    with pytest.raises(MotionError) as info:
        fn(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    return message


def test_missing_file(tmp_path):
    assert "no such BVH file" in _one_line_error(tmp_path / "absent.bvh")
    assert "not a file" in _one_line_error(tmp_path)


def test_not_a_bvh(tmp_path):
    assert "not a BVH" in _one_line_error(write(tmp_path, "hello world\n1 2 3\n"))
    assert "not a BVH" in _one_line_error(write(tmp_path, ""))
    binary = tmp_path / "garbage.bvh"
    binary.write_bytes(bytes(range(256)) * 4)
    assert "binary" in _one_line_error(binary)


def test_truncated_motion(tmp_path):
    text = TINY.replace("Frames: 2", "Frames: 3")
    message = _one_line_error(write(tmp_path, text))
    assert "truncated" in message and "Frames: 3" in message and "2 data lines" in message


def test_truncated_hierarchy(tmp_path):
    cut = TINY[: TINY.index("JOINT Leg")]
    assert "MOTION" in _one_line_error(write(tmp_path, cut))
    assert "ends early" in _one_line_error(write(tmp_path, cut + "MOTION\nFrames: 1\nFrame Time: 0.1\n0 0 0\n"))


def test_wrong_value_count_names_the_line(tmp_path):
    text = TINY.replace("1 2 3  90 0 0  90 0 0  0 0 0  0 0 0", "1 2 3  90 0 0  90 0 0  0 0 0  0 0")
    message = _one_line_error(write(tmp_path, text))
    line = TINY.splitlines().index("1 2 3  90 0 0  90 0 0  0 0 0  0 0 0") + 1
    assert f"line {line}" in message and "14 values" in message and "15 channels" in message


def test_non_numeric_value_names_the_line(tmp_path):
    text = TINY.replace("1 2 3  90 0 0", "1 2 3  9O 0 0")
    message = _one_line_error(write(tmp_path, text))
    line = TINY.splitlines().index("1 2 3  90 0 0  90 0 0  0 0 0  0 0 0") + 1
    assert f"line {line}" in message and "'9O'" in message
    nan = TINY.replace("1 2 3  90 0 0", "1 2 3  nan 0 0")
    assert f"line {line}" in _one_line_error(write(tmp_path, nan))


def test_bad_headers(tmp_path):
    assert "Frames:" in _one_line_error(write(tmp_path, TINY.replace("Frames: 2", "Frames: two")))
    assert "Frame Time" in _one_line_error(write(tmp_path, TINY.replace("Frame Time:\t0.5", "Frame Time: -1")))
    assert "OFFSET" in _one_line_error(write(tmp_path, TINY.replace("OFFSET 0 10 0", "OFFSET 0 ten 0")))
    assert "channel" in _one_line_error(write(tmp_path, TINY.replace("Xrotation Yrotation Zrotation",
                                                                     "Xrotation Yrotation Wrotation")))


def test_extra_data_lines_are_an_error(tmp_path):
    message = _one_line_error(write(tmp_path, TINY.replace("Frames: 2", "Frames: 1")))
    assert "past the declared Frames: 1" in message


# ---------------------------------------------------------------------------- real assets
ASSET_FILES = sorted(MOCAP.glob("*.bvh")) if MOCAP.is_dir() else []
ASSET_PARAMS = [pytest.param(p, id=p.stem) for p in ASSET_FILES] or [
    pytest.param(None, marks=pytest.mark.skip(reason=f"mocap assets not found at {MOCAP} "
                                              "(clone the project next to its shared/ folder)"))]
FAMILY_PARAMS = [mocap_param(p) for p in ASSET_FILES] or ASSET_PARAMS

# (shoulder, elbow, wrist, hip, knee, ankle) joint names of each skeleton family.
FAMILIES = (
    ("LeftArm", "LeftForeArm", "LeftHand", "LeftUpLeg", "LeftLeg", "LeftFoot"),  # CMU MotionBuilder, Mixamo, rokoko
    ("LeftShoulder", "LeftElbow", "LeftWrist", "LeftHip", "LeftKnee", "LeftAnkle"),  # CMU 3dsMax
    ("UpArm_L", "LoArm_L", "Hand_L", "UpLeg_L", "LoLeg_L", "Foot_L"),  # old MakeHuman
    ("lShldr", "lForeArm", "lHand", "lThigh", "lShin", "lFoot"),  # Daz-named CMU release
    ("lhumerus", "lradius", "lhand", "lfemur", "ltibia", "lfoot"),  # CMU ASF names
)
Z_UP = ("animdrawings_fair1_", "makehuman_", "cmu_135_")


def _chain_length(clip: BvhClip, top: int, bottom: int) -> float:
    """Sum of the offset lengths from joint ``top`` down to joint ``bottom`` (orientation-free)."""
    length, j = 0.0, bottom
    while j != top:
        assert j >= 0, f"{clip.joint_names[bottom]} is not below {clip.joint_names[top]}"
        length += float(np.linalg.norm(clip.offsets[j]))
        j = int(clip.parents[j])
    return length


@pytest.mark.parametrize("path", ASSET_PARAMS)
def test_asset_parses_completely(path):
    clip = read_bvh(path)
    declared = int(re.search(r"^\s*Frames:\s*(\d+)", path.read_text(), re.MULTILINE).group(1))
    assert len(clip) == declared
    assert clip.local_rotations.shape == (declared, len(clip.joint_names), 3, 3)
    assert 20 <= clip.fps <= 130
    assert np.all(np.isfinite(clip.root_positions)) and np.all(np.isfinite(clip.local_rotations))
    np.testing.assert_allclose(np.linalg.det(clip.local_rotations), 1.0, atol=1e-9)
    assert clip.parents[0] == -1 and np.all(clip.parents[1:] < np.arange(1, len(clip.parents)))
    _, pos = clip.global_transforms()
    assert np.all(np.isfinite(pos))


@pytest.mark.parametrize("path", FAMILY_PARAMS)
def test_asset_skeleton_is_human_shaped(path):
    clip = read_bvh(path)
    family = next((f for f in FAMILIES if all(n in clip.joint_names for n in f)), None)
    assert family is not None, f"{path.name}: unknown skeleton naming {clip.joint_names[:8]}"
    shoulder, elbow, wrist, hip, knee, ankle = (clip.joint_index(n) for n in family)
    head = next(clip.joint_index(n) for n in clip.joint_names if n.lower() == "head")
    upper_arm = _chain_length(clip, shoulder, elbow)
    forearm = _chain_length(clip, elbow, wrist)
    thigh = _chain_length(clip, hip, knee)
    shin = _chain_length(clip, knee, ankle)
    leg = thigh + shin
    # Bone lengths, not the zero-rotation rest pose: rokoko's offsets all point along local +X.
    assert 0.4 <= upper_arm / thigh <= 1.0
    assert 0.5 <= forearm / upper_arm <= 1.4
    assert 0.7 <= shin / thigh <= 1.3
    assert 0.4 <= _chain_length(clip, 0, head) / leg <= 1.0
    # Frame 0 stands upright along the file's up axis (Y, or Z for the Z-up families).
    _, pos = clip.global_transforms()
    up = 2 if path.name.startswith(Z_UP) else 1
    rise = (pos[0, head] - pos[0, 0]) / leg
    assert rise[up] > 0.4 and np.all(np.abs(np.delete(rise, up)) < 0.25)
    rest = clip.rest_positions()
    assert rest.shape == (len(clip.joint_names), 3) and np.all(rest[0] == 0)
