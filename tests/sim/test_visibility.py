"""Hidden and visible joints: hand-made depth, and a rendered side view against Open3D ray casting."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from swarmpose.body.loader import load_body
from swarmpose.cli.main import main
from swarmpose.core.camera import Intrinsics
from swarmpose.core.errors import ConfigError
from swarmpose.sim.evaluate import joint_errors
from swarmpose.sim.visibility import HIDDEN_MARGIN_M, hidden_joints, split_errors_mm
from swarmpose.sources.registry import open_source

CAMERA = Intrinsics(width=160, height=120, fx=150.0, fy=150.0, cx=80.0, cy=60.0)


def at_pixel(u: float, v: float, z: float) -> list[float]:
    """The camera-frame point (3,) m seen at pixel (u, v) at depth z."""
    return [(u - CAMERA.cx) / CAMERA.fx * z, (v - CAMERA.cy) / CAMERA.fy * z, z]


def test_a_joint_is_hidden_only_where_the_depth_before_it_is_beyond_the_margin():
    depth = np.full((120, 160), 2.0, np.float32)
    depth[:, 120:] = 0.0  # no measurement on the right
    depth[10, 10] = 0.5  # one stray pixel: the window's median ignores it
    joints = np.array([
        at_pixel(40, 60, 2.05),  # just behind the surface it is seen through: visible
        at_pixel(40, 30, 2.0 + HIDDEN_MARGIN_M + 0.05),  # well behind it: hidden
        at_pixel(60, 60, 1.5),  # in front of everything: visible
        at_pixel(140, 60, 2.05),  # where no depth is measured: hidden
        at_pixel(400, 60, 2.05),  # outside the image: hidden
        [np.nan, np.nan, np.nan],  # unknown: hidden
        at_pixel(10, 10, 2.05),  # on the stray pixel: visible
    ])
    assert hidden_joints(depth, CAMERA, joints).tolist() == [False, True, False, True, True, True, False]


def test_bad_shapes_are_named():
    with pytest.raises(ConfigError, match="the camera is 160x120"):
        hidden_joints(np.zeros((10, 10)), CAMERA, np.zeros((2, 3)))
    with pytest.raises(ConfigError, match=r"\(J, 3\)"):
        hidden_joints(np.zeros((120, 160)), CAMERA, np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="must both be"):
        split_errors_mm(joint_errors(np.zeros((2, 3, 3)), np.zeros((2, 3, 3))), np.zeros((2, 2), bool))


def test_the_split_averages_each_side_by_hand():
    truth = np.zeros((2, 3, 3))
    estimates = truth.copy()
    estimates[0, :, 0] = [0.01, 0.02, 0.09]  # frame 0: 10, 20 mm visible; 90 mm hidden
    estimates[1] = np.nan  # a lost frame counts for neither
    hidden = np.array([[False, False, True], [True, True, True]])
    split = split_errors_mm(joint_errors(estimates, truth), hidden)
    assert split["visible_mm"] == pytest.approx(15.0)
    assert split["hidden_mm"] == pytest.approx(90.0)
    assert split["hidden_share"] == pytest.approx(1 / 3)
    assert split_errors_mm(joint_errors(estimates, truth), np.zeros((2, 3), bool))["hidden_mm"] is None


@pytest.fixture(scope="module")
def side_view(tmp_path_factory):
    out = tmp_path_factory.mktemp("side")
    assert main(["synth", "--motion", "builtin:wave", "--frames", "3", "--camera-yaw", "90", "--out", str(out),
                 "--quiet"]) == 0
    return out


def test_a_rendered_side_view_agrees_with_ray_casting_the_posed_body(side_view):
    """The far side's joints are hidden and the near side's seen, as a ray cast from the camera
    to each true joint through the posed body's mesh says (joints within 3 cm of the margin aside)."""
    source = open_source(str(side_view))
    truth = source.ground_truth
    body = load_body("builtin")
    checked = hidden_far = 0
    for frame in source:
        row = truth.row(frame.index)
        joints = truth.joints3d[row]
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(body.pose(truth.poses[row][None])[0].astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(np.asarray(body.triangles, np.int32))
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(mesh)
        directions = joints / np.linalg.norm(joints, axis=1, keepdims=True)
        rays = np.concatenate([np.zeros_like(joints), directions], axis=1).astype(np.float32)
        hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
        in_front = np.linalg.norm(joints, axis=1) - hit  # how far the first surface lies before the joint, m
        oracle = in_front > HIDDEN_MARGIN_M
        clear = np.abs(in_front - HIDDEN_MARGIN_M) > 0.03
        found = hidden_joints(frame.depth, frame.intrinsics, joints)
        assert np.array_equal(found[clear], oracle[clear]), (frame.index, found, oracle, in_front.round(3))
        checked += int(clear.sum())
        hidden_far += int(oracle.sum())
    assert checked >= 30 and hidden_far >= 6  # a side view hides the far limbs
