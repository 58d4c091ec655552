"""The hard-motion design of ``bench accuracy --subset hard`` (issue 53): every motion at every
yaw, at least two shapes a motion, MoveNet and BlazePose; the segments' frame counts; each
sequence turned so that the subject faces the camera of yaw 0 and stays in view."""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import ASSETS, needs_assets

from swarmpose.bench.hard_motions import HARD_MOTIONS, segment_frames
from swarmpose.bench.matrix import YAWS, cells, sequences
from swarmpose.cli.main import main
from swarmpose.core.errors import ConfigError

SIX = {"turning-walk", "sit-stand", "run", "pick-up", "soccer-kick", "front-kick"}


def test_every_hard_motion_meets_every_yaw_two_shapes_and_both_networks():
    hard = cells("hard")
    assert len(hard) == 60 and len({c.name for c in hard}) == 60
    assert {c.sequence.motion for c in hard} == SIX
    for motion in SIX:
        mine = [c for c in hard if c.sequence.motion == motion]
        assert {(c.sequence.yaw_deg, c.detector) for c in mine} == {(y, d) for y in YAWS
                                                                    for d in ("movenet", "blazepose")}
        assert len({c.sequence.shape for c in mine}) >= 2
    assert {c.sequence.shape for c in hard} == {"male", "female", "male-heavy", "female-tall"}


def test_the_hard_regression_subset_is_one_cell_of_the_design():
    small = cells("hard-regression")
    assert len(small) == 1 and small[0].detector == "movenet"
    assert small[0].sequence in sequences("hard")


def test_a_segment_caps_the_frames_and_other_motions_keep_theirs():
    assert segment_frames("turning-walk", 1000) == 168 == HARD_MOTIONS["turning-walk"].frames
    assert segment_frames("run", 40) == 15
    assert segment_frames("pick-up", 40) == 40 and segment_frames("pick-up", 60) == 48
    assert segment_frames("walk", 1000) == 1000


def test_unknown_subset_and_motion_name_the_choices(capsys):
    with pytest.raises(ConfigError, match="hard-regression"):
        sequences("hardest")
    with pytest.raises(ConfigError, match="choose from turning-walk, sit-stand"):
        cells("hard", motions=("walk",))
    assert cells("hard", motions=("run",), detectors=("movenet",))[0].sequence.motion == "run"
    with pytest.raises(SystemExit):
        main(["bench", "accuracy", "--subset", "hardest", "--out", "x"])
    assert "hard-regression" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "accuracy", "--motions", "cartwheel", "--out", "x"])
    assert "turning-walk" in capsys.readouterr().err


def test_sit_stand_is_filmed_with_its_stool_and_bad_props_name_the_sequence():
    from dataclasses import replace

    from swarmpose.bench.accuracy import synth_config

    sit = [s for s in sequences("hard") if s.motion == "sit-stand"]
    assert len(sit) == len(YAWS) and all(s.props == ("stool",) and s.name.endswith("-stool") for s in sit)
    assert all(s.props == () for s in sequences("hard") if s.motion != "sit-stand")
    (stool,) = synth_config(sit[0], 10).props
    assert (stool.kind, stool.person, stool.box) == ("stool", 1, None)
    bad = replace(sit[0], props=("bench",))
    with pytest.raises(ConfigError, match=re.escape(f"sequence {bad.name}: prop 'bench': unknown prop")):
        synth_config(bad, 10)


@pytest.mark.slow
@needs_assets
def test_the_stool_stands_where_the_whole_segment_sits_whatever_is_filmed(tmp_path):
    """The benchmark's stool is placed over the whole segment, not over the frames filmed (in the
    first frames nobody sits yet, and synth would refuse a stool placed there): the same stool for
    1 and 3 frames filmed, as high as a low stool's seat."""
    import json

    from swarmpose.bench.accuracy import make_sequence

    seq = [s for s in sequences("hard") if s.motion == "sit-stand"][0]
    stools = []
    for frames in (1, 3):
        folder = make_sequence(seq, tmp_path / f"{seq.name}-{frames}", frames, ASSETS)
        (stool,) = json.loads((folder / "sequence.json").read_text())["props"]
        stools.append(stool)
    assert stools[0] == stools[1] and stools[0]["kind"] == "stool"
    assert 0.15 < stools[0]["world"]["size_m"][1] < 0.6


@needs_assets
def test_each_sequence_faces_the_camera_of_yaw_0_at_its_first_frame(tmp_path):
    """The angle on the floor between the rendered torso's facing and the direction from the
    pelvis to the camera is the camera's yaw."""
    import json

    from swarmpose.bench.accuracy import make_sequence
    from swarmpose.body.skeleton import EVAL_JOINTS
    from swarmpose.sim.evaluate import torso_facing

    for seq in [s for s in sequences("hard") if s.motion == "soccer-kick"]:
        folder = make_sequence(seq, tmp_path / seq.name, 1, ASSETS)
        first = json.loads((folder / "groundtruth.jsonl").read_text().splitlines()[0])
        joints = np.array([[first["joints3d"][n] for n in EVAL_JOINTS]])
        rotation = np.array(json.loads((folder / "sequence.json").read_text())["camera"]["world_to_camera_rotation"])
        up = rotation @ np.array([0.0, 1.0, 0.0])
        pelvis = (joints[0, EVAL_JOINTS.index("left_hip")] + joints[0, EVAL_JOINTS.index("right_hip")]) / 2

        facing, to_camera = (v - (v @ up) * up for v in (torso_facing(joints)[0], -pelvis))  # on the floor
        cos = facing @ to_camera / np.linalg.norm(facing) / np.linalg.norm(to_camera)
        angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        assert angle == pytest.approx(seq.yaw_deg, abs=15.0), seq.name


@pytest.mark.slow
@needs_assets
def test_every_hard_sequence_keeps_the_subject_in_view():
    """Every evaluation joint of every frame of every segment projects inside the image (the
    travelling motions from the far placement)."""
    from dataclasses import replace

    from swarmpose.bench.accuracy import synth_config
    from swarmpose.body.kinematics import transform_points
    from swarmpose.body.skeleton import EVAL_JOINTS
    from swarmpose.sim.scene import PersonSpec, load_people
    from swarmpose.sim.synth import place_scene

    for seq in sequences("hard"):
        clip = HARD_MOTIONS[seq.motion]
        config = synth_config(seq, clip.frames)
        spec = PersonSpec(f"makehuman:{ASSETS}/bodies/makehuman", seq.shape, str(ASSETS / clip.clip),
                          start_s=clip.start_s)
        person = load_people([spec], config.frames, config.fps)[0]
        forward = person.motion.root_rotation[0][:, 2]
        person = replace(person, spec=replace(spec, yaw_deg=-np.degrees(np.arctan2(forward[0], forward[2]))))
        poses = place_scene([person], config).poses[0]
        body = person.body
        index = [body.point_names.index(n) for n in EVAL_JOINTS]
        points = transform_points(body.point_bones, body.point_rest, body.transforms(poses))[:, index]
        pixels = config.intrinsics.project(points.reshape(-1, 3)).reshape(len(poses), -1, 2)
        size = np.array([config.intrinsics.width, config.intrinsics.height])
        assert np.all((pixels > 0) & (pixels < size)) and np.all(points[..., 2] > 1.0), seq.name


HARD_SETTINGS = {"particles": 32, "generations": 32}
HARD_FRAMES = 60
"""The turning walk's first two seconds: the first 90° turn (the pelvis 172° -> 322° of the clip)."""
HARD_BOUND_MM = 70.0
"""Hybrid Δ bound (measured 54.2 mm at p = g = 32 on 2026-11-28; joints-only 125.9 mm, ratio 0.43)."""
HARD_RATIO = 0.65
"""Issue 53's goal for the ratio to joints-only."""


@pytest.fixture(scope="module")
def hard_regression(tmp_path_factory):
    from swarmpose.bench.accuracy import run_matrix

    return run_matrix(tmp_path_factory.mktemp("hard"), subset="hard-regression", modes=("hybrid", "joints"),
                      frames=HARD_FRAMES, tracker=HARD_SETTINGS, assets=ASSETS, progress=False)


@pytest.mark.slow
@needs_assets
def test_the_turning_walk_from_the_front_turns_without_a_flip(hard_regression):
    by = {r["mode"]: r for r in hard_regression}
    assert sorted(by) == ["hybrid", "joints"]
    hybrid, joints = by["hybrid"], by["joints"]
    assert hybrid["frames"] == HARD_FRAMES and hybrid["detector"] == "movenet" and hybrid["motion"] == "turning-walk"
    assert hybrid["flipped"] == 0 and hybrid["sides_swapped"] == 0 and hybrid["flips"] == 0, hybrid
    assert hybrid["recovery_max_s"] is None and hybrid["lost"] == 0
    assert hybrid["mpjpe_mm"] <= HARD_BOUND_MM, hybrid
    assert hybrid["mpjpe_mm"] <= HARD_RATIO * joints["mpjpe_mm"], (hybrid, joints)
