"""A person sitting down on a stool, tracked (issue 53): the body is not fitted into the stool."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import MAKEHUMAN, MOCAP, needs_assets

import swarmpose
from swarmpose.cli.main import main
from swarmpose.sim.scoring import body_joints
from swarmpose.sources.groundtruth import load_ground_truth

SEED = 1
"""The PSO seed of the run: one where the stool left in the depth puts a leg inside it (main at 814760e,
before props: knees or ankles inside in 0, 11, 2 and 2 of the 24 seated frames for seeds 0-3; seed 0
would pass without props)."""
SEAT_CLEARANCE_M = 0.06
"""The tracked hip joints stay at least this far (m) above the stool's top while seated: the truth's
are 0.11-0.13 m above it; measured 0.088-0.137 over seeds 0-3 (`swarmpose eval --seed N`)."""
DELTA_BOUND_MM = 100.0
"""Δ of the run: 56.7 mm measured (seed 1; 74.3, 56.7, 82.5, 86.9 for seeds 0-3; 64.2, 87.1, 109.9,
101.2 before props were left out of the depth, main at 814760e)."""


def _to_box(points: np.ndarray, stool: dict, r_cw: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """Camera-frame points (..., 3) m in the stool's own frame (origin: its footprint's centre)."""
    yaw = np.radians(stool["world"]["yaw_deg"])
    axes = np.array([[np.cos(yaw), 0.0, -np.sin(yaw)], [0.0, 1.0, 0.0], [np.sin(yaw), 0.0, np.cos(yaw)]])
    world = points @ r_cw + eye
    return (world - np.array(stool["world"]["centre_floor_m"])) @ axes.T


@needs_assets
@pytest.mark.slow
def test_a_person_sitting_down_on_a_stool_is_not_fitted_into_it(tmp_path):
    """The MakeHuman male walks to the stool and sits down (the sit-stand clip from 0.6 s, 45 frames
    at 15 fps), seen from the side, where the stool's face lies beside the near leg. The stool is a
    prop from the 5th frame, before he sits; then no tracked knee or ankle is inside it (before
    props were left out of the depth: in 11 of the 24 seated frames with this seed, see
    :data:`SEED`; none since, for seeds 0-3) and the tracked hips stay above its top."""
    out = tmp_path / "sit"
    person = f"makehuman:{MAKEHUMAN}:male:{MOCAP / 'cmu_14_31_sit_stepstool_standup.bvh'}@0,0,0,0.6"
    assert main(["synth", "--person", person, "--fps", "15", "--frames", "45", "--camera-yaw", "90",
                 "--prop", "stool", "--out", str(out), "--quiet"]) == 0
    meta = json.loads((out / "sequence.json").read_text())
    (stool,) = meta["props"]
    r_cw, eye = np.array(meta["camera"]["world_to_camera_rotation"]), np.array(meta["camera"]["eye_world_m"])
    truth = load_ground_truth(out)
    results = list(swarmpose.track(f"folder:{out}", body=f"makehuman:{MAKEHUMAN}", detector="simulated",
                                   seed=SEED))
    tracked = np.array([body_joints(r.bodies[0].to_message()) if r.bodies else np.full((14, 3), np.nan)
                        for r in results])
    errors = 1000 * np.linalg.norm(tracked - truth.joints3d, axis=-1)
    delta = float(np.nanmean(errors))
    seat = stool["world"]["size_m"][1]
    hips = slice(8, 10)  # EVAL_JOINTS: left_hip, right_hip
    true_hips = _to_box(truth.joints3d[:, hips], stool, r_cw, eye)[..., 1]
    seated = np.flatnonzero(true_hips.max(axis=1) < seat + 0.2)
    assert len(seated) >= 15  # he sits for the second half of the run
    tracked_hips = _to_box(tracked[seated][:, hips], stool, r_cw, eye)[..., 1]
    assert np.nanmin(tracked_hips) > seat + SEAT_CLEARANCE_M, np.nanmin(tracked_hips) - seat
    legs = _to_box(tracked[seated][:, 10:14], stool, r_cw, eye)  # knees and ankles
    half = np.array([stool["world"]["size_m"][0], 0.0, stool["world"]["size_m"][2]]) / 2
    inside = (np.abs(legs[..., 0]) < half[0] - 0.03) & (np.abs(legs[..., 2]) < half[2] - 0.03) & \
             (legs[..., 1] < seat - 0.03)
    assert not inside.any()
    assert delta < DELTA_BOUND_MM, delta
