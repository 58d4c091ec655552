"""Reading a clip's skeleton: joint maps, units and up axes, and the errors of a clip that cannot be read.

Oracles: the clip read under its own names (whose retargeting tests/motion/test_mocap.py checks
against the clip's joint angles) for a renamed copy read through a map file; the facts the assets'
README states for each family (units, up axis, the stool clip's hip heights, the run's distance).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import MOCAP, needs_assets

from swarmpose.core.errors import MotionError
from swarmpose.motion.bvh import read_bvh
from swarmpose.motion.library import load_motion_spec, split_motion_spec
from swarmpose.motion.retarget import ReadOptions, read_clip

DAZ = ("cmu_02_06_bend_scoop_pickup", "cmu_06_10_dribble_walk_left_turns", "cmu_09_01_run", "cmu_10_01_soccer_kick",
       "cmu_14_31_sit_stepstool_standup")
ASF = "cmu_135_04_front_kick"

# The joint at each point of the body, per family, written out from the files' hierarchies.
DAZ_NAMES = {"neck": "neck", "head": "head", "left_collar": "lCollar", "right_collar": "rCollar",
             "left_shoulder": "lShldr", "right_shoulder": "rShldr", "left_elbow": "lForeArm",
             "right_elbow": "rForeArm", "left_wrist": "lHand", "right_wrist": "rHand", "left_hip": "lThigh",
             "right_hip": "rThigh", "left_knee": "lShin", "right_knee": "rShin", "left_ankle": "lFoot",
             "right_ankle": "rFoot"}
ASF_NAMES = {"neck": "lclavicle", "head": "head", "left_collar": "lclavicle", "right_collar": "rclavicle",
             "left_shoulder": "lhumerus", "right_shoulder": "rhumerus", "left_elbow": "lradius",
             "right_elbow": "rradius", "left_wrist": "lhand", "right_wrist": "rhand", "left_hip": "lfemur",
             "right_hip": "rfemur", "left_knee": "ltibia", "right_knee": "rtibia", "left_ankle": "lfoot",
             "right_ankle": "rfoot", "left_toe": "ltoes", "right_toe": "rtoes"}

# (clip name prefix, up axis, units) as ../shared/assets/README.md states them (None: not stated).
README_FACTS = [(name, "+y", "cm") for name in DAZ] + [
    (ASF, "+z", "in"),
    ("bvh11_131_01", "+y", "cmu"), ("bvh11_131_03", "+y", "cmu"), ("animdrawings_cmu1_jumping_jacks", "+y", "cmu"),
    ("bvh11_scaled_131_02", "+y", "m"),
    ("animdrawings_rokoko_jesse_dance", "+y", "cm"),
    ("animdrawings_fair1_dab", "+z", None), ("animdrawings_fair1_wave_hello", "+z", None),
    ("makehuman_walk1", "+z", None), ("makehuman_zombieWalk1", "+z", None),
]

ROBOT = ("HIERARCHY\nROOT Base\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
         "Yrotation\n JOINT Arm\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n"
         "   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.0333\n0 0 0 0 0 0 0 0 0\n")


def first_frames(source: Path, out: Path, frames: int, rename: dict[str, str] | None = None) -> Path:
    """A copy of the BVH ``source`` cut to its first ``frames`` frames, joints renamed by ``rename``."""
    head, motion = source.read_text().split("MOTION", 1)
    lines = [line for line in motion.splitlines() if line.strip()]
    if rename:
        head = re.sub(r"^(\s*(?:ROOT|JOINT)\s+)(\S+)\s*$", lambda m: m.group(1) + rename.get(m.group(2), m.group(2)),
                      head, flags=re.M)
    data = "\n".join(lines[2:2 + frames])
    out.write_text(f"{head}MOTION\nFrames: {frames}\n{lines[1]}\n{data}\n")
    return out


def toml_map(path: Path, names: dict[str, str], extra: str = "") -> Path:
    path.write_text(extra + "[joints]\n" + "".join(f'{k} = "{v}"\n' for k, v in names.items()))
    return path


@needs_assets
@pytest.mark.parametrize(("clip", "names"), [(DAZ[1], DAZ_NAMES), (ASF, ASF_NAMES)], ids=["daz", "asf"])
def test_a_renamed_clip_read_through_a_map_file_retargets_as_the_original(tmp_path, makehuman_male, clip, names):
    body = makehuman_male
    original = first_frames(MOCAP / f"{clip}.bvh", tmp_path / "original.bvh", 240)
    joints = read_bvh(original).joint_names
    rename = {name: f"bone_{k:02d}" for k, name in enumerate(joints)}  # nothing a family would recognise
    renamed = first_frames(MOCAP / f"{clip}.bvh", tmp_path / "renamed.bvh", 240, rename)
    with pytest.raises(MotionError, match="unknown BVH skeleton"):
        load_motion_spec(str(renamed), body, 0, 30.0)
    mapping = toml_map(tmp_path / "names.toml", {key: rename[name] for key, name in names.items()})
    want = load_motion_spec(str(original), body, 0, 30.0)
    got = load_motion_spec(f"{renamed}?map={mapping}", body, 0, 30.0)
    np.testing.assert_array_equal(got.angles, want.angles)
    np.testing.assert_array_equal(got.root_rotation, want.root_rotation)
    np.testing.assert_array_equal(got.root_offset, want.root_offset)


@needs_assets
@pytest.mark.parametrize(("name", "up", "units"), README_FACTS, ids=[f[0] for f in README_FACTS])
def test_up_axis_and_units_are_detected_as_the_readme_states(name, up, units):
    frame = read_clip(read_bvh(MOCAP / f"{name}.bvh").resample(10.0)).frame
    assert frame.up == up and not frame.up_stated
    if units is not None:
        assert frame.units == units and not frame.units_stated


@needs_assets
def test_detected_units_give_the_readme_figures_in_metres():
    """The README: the stool clip's hips go 0.84 -> 0.40 m; the run covers 4 m in 1.2 s."""
    from swarmpose.motion.clip_frame import UNITS

    def pelvis_path(name: str):
        reading = read_clip(read_bvh(MOCAP / f"{name}.bvh"))
        metres = UNITS[reading.frame.units]
        along = reading.positions @ reading.frame.up_vector
        pelvis = reading.positions[:, reading.roles.index["pelvis"]]
        height = (along[:, reading.roles.index["pelvis"]] - along.min()) * metres
        flat = (pelvis - np.outer(pelvis @ reading.frame.up_vector, reading.frame.up_vector)) * metres
        return height, flat

    height, _ = pelvis_path("cmu_14_31_sit_stepstool_standup")
    assert abs(height[0] - 0.84) < 0.03 and abs(height.min() - 0.40) < 0.03
    _, flat = pelvis_path("cmu_09_01_run")
    assert abs(np.linalg.norm(flat[-1] - flat[0]) - 4.0) < 0.3


@needs_assets
def test_stated_units_and_up_are_used_and_checked(tmp_path):
    clip = read_bvh(first_frames(MOCAP / f"{DAZ[0]}.bvh", tmp_path / "daz.bvh", 60))
    frame = read_clip(clip, ReadOptions(units="cm", up="+y")).frame
    assert (frame.up, frame.units, frame.up_stated, frame.units_stated) == ("+y", "cm", True, True)
    with pytest.raises(MotionError, match=r"in m its skeleton would stand 153 m tall; its size suggests cm"):
        read_clip(clip, ReadOptions(units="m"))
    with pytest.raises(MotionError, match=r"standing upright along \+z \(stated\); state its up axis"):
        read_clip(clip, ReadOptions(up="+z"))
    # The map file's own units and up, overridden by the spec's.
    mapping = toml_map(tmp_path / "names.toml", DAZ_NAMES, 'units = "in"\nup = "y"\n')
    _, options = split_motion_spec(f"{tmp_path / 'daz.bvh'}?map={mapping}&units=cm")
    frame = read_clip(clip, options).frame
    assert (frame.up, frame.units) == ("+y", "cm") and frame.up_stated


def test_an_unmappable_clip_names_the_joints_it_lacks_and_the_map(tmp_path):
    bvh = tmp_path / "robot.bvh"
    bvh.write_text(ROBOT)
    with pytest.raises(MotionError) as info:
        read_clip(read_bvh(bvh))
    message = str(info.value)
    assert "unknown BVH skeleton" in message and "its joints (Base, Arm)" in message
    assert "?map=names.toml" in message and "left_shoulder" in message


@needs_assets
def test_a_clip_one_joint_short_of_a_family_names_that_joint(tmp_path):
    clip = first_frames(MOCAP / f"{DAZ[0]}.bvh", tmp_path / "daz.bvh", 10, {"lShldr": "LeftUpperArm"})
    with pytest.raises(MotionError, match=r"the nearest, Daz \(CMU cgspeed release\), lacks lShldr; name your "
                                          r"joints in a TOML file and pass it as FILE.bvh\?map=names.toml"):
        read_clip(read_bvh(clip))


def test_a_map_that_lacks_keys_or_names_absent_joints_says_which(tmp_path):
    bvh = tmp_path / "robot.bvh"
    bvh.write_text(ROBOT)
    partial = toml_map(tmp_path / "partial.toml", {"neck": "Arm", "head": "Arm"})
    with pytest.raises(MotionError, match=r"lacks left_collar, left_shoulder, .*right_ankle"):
        read_clip(read_bvh(bvh), split_motion_spec(f"{bvh}?map={partial}")[1])
    wrong = toml_map(tmp_path / "wrong.toml", {**DAZ_NAMES, "left_elbow": "Arm"})
    with pytest.raises(MotionError, match=r"no joint for neck = 'neck', head = 'head'.*it has Base, Arm"):
        read_clip(read_bvh(bvh), split_motion_spec(f"{bvh}?map={wrong}")[1])


@pytest.mark.parametrize(("spec", "message"), [
    ("clip.bvh?units=furlong", "units='furlong' is not a unit"),
    ("clip.bvh?up=w", "up='w' is not an axis"),
    ("clip.bvh?scale=2", "options after '?' are map=FILE.toml, units=UNIT, up=AXIS and hold=[AT:]SECONDS"),
    ("clip.bvh?up=y&up=z", "each once"),
    ("clip.bvh?map=", "map has no value"),
    ("clip.bvh?map=nowhere.toml", "joint map nowhere.toml does not exist; check the path after ?map="),
])
def test_bad_spec_options_are_named(spec, message):
    with pytest.raises(MotionError, match=re.escape(message)):
        split_motion_spec(spec)


@pytest.mark.parametrize(("text", "message"), [
    ("joints = [", "is not valid TOML"),
    ('units = "cm"\n', "has no [joints] table"),
    ('[joints]\nelbow = "E"\n', "unknown keys ['elbow']"),
    ("[joints]\nneck = 3\n", "['neck'] must be BVH joint names"),
    ('scale = 2\n[joints]\nneck = "N"\n', "unknown settings ['scale']"),
])
def test_bad_map_files_are_named(tmp_path, text, message):
    path = tmp_path / "names.toml"
    path.write_text(text)
    with pytest.raises(MotionError, match=re.escape(message)):
        split_motion_spec(f"clip.bvh?map={path}")
