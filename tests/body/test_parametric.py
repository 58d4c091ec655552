"""The built-in parametric body: shape, closure, skinning, named points, posing, parsing.

Oracles: trimesh (watertightness, signed volume), Open3D ray casting (signed distance,
occupancy, ray hits), anthropometric tables (segment heights as fractions of stature),
and the rest-pose identity of linear-blend and dual-quaternion skinning.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
import trimesh

from swarmpose.body import skeleton as sk
from swarmpose.body.parametric import BONE_NAMES, build_parametric_body
from swarmpose.body.parametric_shape import BUILTIN_PRESETS, BodyShape, parse_shape
from swarmpose.core.errors import ConfigError

JOINT_CENTRES = ("head", "neck", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
                 "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
                 "mid_hip", "spine", "left_clavicle", "right_clavicle")
SURFACE_POINTS = ("nose", "left_ear", "right_ear", "left_heel", "right_heel", "left_toe", "right_toe")


@pytest.fixture(scope="module")
def body():
    return build_parametric_body()


def _scene(b) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(b.vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(b.triangles, dtype=np.uint32)))
    return scene


def _signed_distance(b, points: np.ndarray) -> np.ndarray:
    return _scene(b).compute_signed_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def _dense(b) -> np.ndarray:
    dense = np.zeros((len(b.vertices), len(b.bone_names)))
    np.add.at(dense, (np.arange(len(b.vertices))[:, None], b.skin_indices), b.skin_weights)
    return dense


def _floor_height(b, point: str) -> float:
    """Height of named point above the soles as a fraction of stature."""
    return (b.point(point)[1] + b.floor_offset) / b.height


# ---------------------------------------------------------------------------- shape
@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(BUILTIN_PRESETS))
def test_every_preset_builds_at_its_height(name):
    shape = BUILTIN_PRESETS[name]
    assert 1.55 <= shape.height <= 1.95
    b = build_parametric_body(shape)
    extent = np.ptp(b.vertices[:, 1])
    assert abs(extent - shape.height) / shape.height < 0.02
    assert b.name == ("builtin" if name == "default" else f"builtin:{name}")
    assert b.metadata["source"] == "builtin" and b.metadata["shape"]["height"] == shape.height
    assert 9_000 <= len(b.triangles) <= 12_000
    assert trimesh.Trimesh(b.vertices, b.triangles, process=False).is_watertight


def test_presets_differ_as_named():
    vol = {n: trimesh.Trimesh(build_parametric_body(s).vertices, build_parametric_body(s).triangles,
                              process=False).volume for n, s in BUILTIN_PRESETS.items()}
    assert vol["male-heavy"] > 1.3 * vol["male"]
    assert vol["female-slim"] < vol["female"] * 1.68 / 1.65
    male, female = (build_parametric_body(BodyShape(sex=s)) for s in ("male", "female"))
    span = lambda b, a, c: b.point(a)[0] - b.point(c)[0]
    assert span(male, "left_shoulder", "right_shoulder") > span(female, "left_shoulder", "right_shoulder")
    assert span(male, "left_hip", "right_hip") < span(female, "left_hip", "right_hip")


def _waist_area(b) -> float:
    """Cross-section area (m^2) of the torso at 0.62 H, by ray-cast occupancy on a 2 mm grid."""
    y = 0.62 * b.height - b.floor_offset
    step = 0.002
    xs = np.arange(-0.3, 0.3, step)
    x, z = np.meshgrid(xs, xs, indexing="ij")
    pts = np.stack([x, np.full_like(x, y), z], -1).reshape(-1, 3)
    occ = _scene(b).compute_occupancy(o3d.core.Tensor(pts.astype(np.float32))).numpy()
    return float(occ.sum() * step * step)


@pytest.mark.slow
def test_torso_girth_grows_the_waist():
    thin, base, thick = (build_parametric_body(BodyShape(torso_girth=g)) for g in (0.8, 1.0, 1.3))
    a_thin, a_base, a_thick = (_waist_area(b) for b in (thin, base, thick))
    assert 0.04 < a_base < 0.09  # a 0.70-0.95 m waist
    assert 1.4 < a_thick / a_base < 1.9  # radii x1.3 -> area x1.69
    assert 0.55 < a_thin / a_base < 0.75  # radii x0.8 -> area x0.64
    assert abs(thick.height - base.height) < 0.005


def _upper_arm_radius(b) -> float:
    """Distance from the mid upper-arm axis to the skin straight ahead (+Z), m."""
    mid = 0.5 * (b.point("left_shoulder") + b.point("left_elbow"))
    ray = o3d.core.Tensor(np.r_[mid, 0.0, 0.0, 1.0][None].astype(np.float32))
    return float(_scene(b).cast_rays(ray)["t_hit"].numpy()[0])


def test_arm_girth_thickens_the_arms_only():
    base, thick = build_parametric_body(), build_parametric_body(BodyShape(arm_girth=1.4))
    r0, r1 = _upper_arm_radius(base), _upper_arm_radius(thick)
    assert 0.03 < r0 < 0.06
    assert 1.3 < r1 / r0 < 1.5
    assert abs(thick.height - base.height) < 0.005
    assert abs(_waist_area(thick) - _waist_area(base)) < 0.01 * _waist_area(base)


def test_mesh_is_closed_and_outward(body):
    mesh = trimesh.Trimesh(body.vertices, body.triangles, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.euler_number == 2 and len(mesh.split(only_watertight=False)) == 1
    assert 0.05 < mesh.volume < 0.11  # human density ~1 kg/L, 50-110 kg
    o3d_mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(body.vertices)),
                                         o3d.utility.Vector3iVector(np.array(body.triangles)))
    assert o3d_mesh.is_edge_manifold() and o3d_mesh.is_watertight()
    normals = mesh.face_normals
    centres = mesh.triangles_center
    assert normals[np.argmax(centres[:, 1]), 1] > 0.9  # crown faces up
    assert normals[np.argmax(centres[:, 0]), 0] > 0.5  # left fingertips face left
    assert normals[np.argmax(centres[:, 2]), 2] > 0.5  # most forward point (toes or nose) faces forward


def test_rest_pose_is_upright_and_symmetric(body):
    v = body.vertices
    mesh = trimesh.Trimesh(v, body.triangles, process=False)
    assert abs(mesh.center_mass[0]) < 0.005  # volume centroid on the mid-sagittal plane
    assert np.ptp(v[:, 0]) > 0.8 * body.height  # A-pose: hands well away from the body
    assert np.ptp(v[:, 2]) < 0.25 * body.height


# ---------------------------------------------------------------------------- skinning
def test_skin_weights_are_sparse_normalised_and_local(body):
    w, idx = body.skin_weights, body.skin_indices
    assert w.shape == (len(body.vertices), 4) and idx.max() < len(BONE_NAMES)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-5)
    assert np.all(w >= 0)
    dense = _dense(body)
    bone = {n: i for i, n in enumerate(body.bone_names)}
    v = body.vertices
    sh, el, wr = (body.point(f"left_{p}") for p in ("shoulder", "elbow", "wrist"))
    axis = (wr - sh) / np.linalg.norm(wr - sh)
    along = (v - wr) @ axis
    hand = (along > 0.04) & (np.linalg.norm(v - wr - np.outer(along, axis), axis=1) < 0.1)
    assert hand.sum() > 20
    assert np.all(dense[hand, bone["left_hand"]] + dense[hand, bone["left_forearm"]] > 0.99)
    assert np.all(dense[hand, bone["left_hand"]] > 0.5)
    at_elbow = (np.abs((v - el) @ axis) < 0.01) & (np.linalg.norm(v - el, axis=1) < 0.08)
    assert at_elbow.sum() > 10  # smooth blend across the joint
    assert np.all(dense[at_elbow, bone["left_upper_arm"]] > 0.2) and np.all(dense[at_elbow, bone["left_forearm"]] > 0.2)
    soles = v[:, 1] < -body.floor_offset + 0.02
    assert np.all(dense[soles, bone["left_foot"]] + dense[soles, bone["right_foot"]] > 0.85)
    crown = v[:, 1] > body.point("nose")[1]
    assert np.all(dense[crown, bone["head"]] > 0.75)
    left_arm = v[:, 0] > 0.3
    right_bones = [i for n, i in bone.items() if n.startswith("right_")]
    assert left_arm.sum() > 100 and dense[np.ix_(left_arm, right_bones)].max() == 0.0


def test_bones_map_onto_the_tracking_skeleton(body):
    assert body.bone_names[0] == "pelvis" and body.bone_parents[0] == -1
    assert np.all(body.bone_parents[1:] < np.arange(1, len(body.bone_names)))
    np.testing.assert_allclose(body.bone_heads[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(body.bind_matrices[:, :3, 3], body.bone_heads)
    joint_of = {n: (sk.JOINT_NAMES[j] if j >= 0 else None) for n, j in zip(body.bone_names, body.bone_joint)}
    assert joint_of["left_forearm"] == "left_elbow" and joint_of["right_shin"] == "right_knee"
    assert joint_of["head"] is None and joint_of["left_hand"] is None and joint_of["pelvis"] is None
    assert body.bones_of_joint("spine") == [1, 2]
    np.testing.assert_allclose(body.bone_fraction[[1, 2]], 0.5)


# ---------------------------------------------------------------------------- named points
def test_named_points_sit_where_anatomy_says(body):
    p = body.point
    assert set(sk.POINT_NAMES) <= set(body.point_names)
    for name in body.point_names:
        if name.startswith("left_"):
            assert p(name)[0] > 0, name
            mirror = p("right_" + name[5:]) * [-1, 1, 1]
            tol = 1e-9 if name in JOINT_CENTRES else 0.01
            np.testing.assert_allclose(p(name), mirror, atol=tol, err_msg=name)
        if name.startswith("right_"):
            assert p(name)[0] < 0, name
    # Drillis-Contini heights (fraction of stature)
    for name, frac in (("left_hip", 0.53), ("left_knee", 0.285), ("left_ankle", 0.039), ("left_shoulder", 0.80),
                       ("neck", 0.83), ("left_eye", 0.936)):
        assert abs(_floor_height(body, name) - frac) < 0.02, name
    arm = np.linalg.norm(p("left_wrist") - p("left_shoulder")) / body.height
    assert abs(arm - (0.818 - 0.485)) < 0.02  # shoulder-to-wrist = 0.333 H when hanging straight
    assert 0.48 < _floor_height(body, "left_wrist") < 0.60  # A-pose lifts it from 0.485 H
    assert p("left_knee")[1] < p("left_hip")[1] and p("left_ankle")[1] < p("left_knee")[1]
    assert p("left_wrist")[1] < p("left_elbow")[1] < p("left_shoulder")[1] < p("neck")[1] < p("head")[1]
    np.testing.assert_allclose(p("mid_hip"), 0.5 * (p("left_hip") + p("right_hip")), atol=1e-12)
    assert p("nose")[2] > p("head")[2] + 0.07 and p("nose")[1] < p("left_eye")[1]
    assert p("left_eye")[2] > p("left_ear")[2] + 0.05
    assert p("left_toe")[2] > p("left_ankle")[2] + 0.12 and p("left_heel")[2] < p("left_ankle")[2] - 0.03
    assert p("spine")[1] > p("mid_hip")[1] and p("left_clavicle")[0] < p("left_shoulder")[0]


def test_named_points_are_inside_or_on_the_skin(body):
    inner = _signed_distance(body, body.point_rest[body.point_indices(JOINT_CENTRES)])
    assert np.all(inner < 0) and np.all(inner > -0.15)
    assert np.all(_signed_distance(body, body.point_rest[body.point_indices(sk.EVAL_JOINTS)]) > -0.1)
    skin = _signed_distance(body, body.point_rest[body.point_indices(SURFACE_POINTS)])
    assert np.all(np.abs(skin) < 0.01)


def test_points_are_carried_by_their_segment(body):
    carrier = {n: body.bone_names[b] for n, b in zip(body.point_names, body.point_bones)}
    assert carrier["left_elbow"] == "left_forearm" and carrier["right_wrist"] == "right_hand"
    assert carrier["nose"] == "head" and carrier["left_toe"] == "left_foot" and carrier["mid_hip"] == "pelvis"


# ---------------------------------------------------------------------------- posing
@pytest.mark.parametrize("skinning", ["lbs", "dqs"])
def test_rest_pose_reproduces_the_rest_mesh(body, skinning):
    np.testing.assert_allclose(body.pose(body.rest_pose(), skinning)[0], body.vertices, atol=1e-6)
    np.testing.assert_allclose(body.posed_points(body.rest_pose())[0], body.point_rest, atol=1e-9)


def test_rest_angles_are_inside_table_1_and_zero_is_the_t_pose(body):
    rest = body.rest_angles
    assert np.all(rest > sk.ANGLE_LIMITS[:, 0] - 1e-9) and np.all(rest < sk.ANGLE_LIMITS[:, 1] + 1e-9)
    left_roll = rest[sk.angle_offset("left_shoulder")]
    assert -0.95 < left_roll < -0.5  # A-pose: arm lowered ~40-45 degrees from the T-pose
    t_pose = sk.neutral_pose(translation=(0.0, 0.0, 0.0), quaternion=(1.0, 0.0, 0.0, 0.0))
    pts = dict(zip(body.point_names, body.posed_points(t_pose)[0]))
    unit = lambda a, b: (pts[b] - pts[a]) / np.linalg.norm(pts[b] - pts[a])
    # the spine bends at two pivots (half the angle each), so its chord is only nearly exact
    for a, b, direction, tol in (("left_shoulder", "left_wrist", sk.X, 1e-6),
                                 ("right_shoulder", "right_wrist", sk.NEG_X, 1e-6),
                                 ("left_clavicle", "left_shoulder", sk.X, 1e-6), ("spine", "neck", sk.Y, 0.01),
                                 ("left_hip", "left_ankle", (0, -1, 0), 1e-6), ("right_heel", "right_toe", sk.Z, 1e-6)):
        np.testing.assert_allclose(unit(a, b), direction, atol=tol, err_msg=f"{a}->{b}")


def test_bending_the_left_elbow_moves_only_the_left_forearm(body):
    h = body.rest_pose()
    h[7 + sk.angle_offset("left_elbow")] = -1.5
    names = ["left_elbow", "left_wrist", "right_wrist"]
    rest = body.posed_points(body.rest_pose(), names)[0]
    bent = body.posed_points(h, names)[0]
    np.testing.assert_allclose(bent[0], rest[0], atol=1e-12)
    np.testing.assert_allclose(bent[2], rest[2], atol=1e-12)
    assert np.linalg.norm(bent[1] - rest[1]) > 0.2
    assert bent[1][2] > rest[1][2] + 0.15  # flexion brings the hand forward
    assert np.isclose(np.linalg.norm(bent[1] - bent[0]), np.linalg.norm(rest[1] - rest[0]))
    hand = _dense(body)[:, body.bone_names.index("left_hand")] > 0.99
    right = body.vertices[:, 0] < -0.2
    for skinning in ("lbs", "dqs"):
        verts = body.pose(h, skinning)[0]
        np.testing.assert_allclose(verts[right], body.vertices[right], atol=1e-6)
        # the hand's skin follows the posed wrist rigidly
        d_rest = np.linalg.norm(body.vertices[hand] - rest[1], axis=1)
        d_bent = np.linalg.norm(verts[hand] - bent[1], axis=1)
        np.testing.assert_allclose(d_bent, d_rest, atol=1e-3)


def test_tracking_lod_keeps_skinning(body):
    lod = body.tracking_lod(1500)
    assert 1300 <= len(lod.triangles) <= 1700
    np.testing.assert_allclose(lod.skin_weights.sum(axis=1), 1.0, atol=1e-5)
    assert abs(lod.height - body.height) < 0.03


def test_tracking_lod_is_kept_in_the_cache_and_read_back_unchanged(body, monkeypatch, tmp_path):
    """A second process's level of detail comes from the cache (the decimation not run again) and
    equals the decimation computed afresh; another mesh gets an entry of its own."""
    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(tmp_path))
    first = body.tracking_lod(1500)
    assert len(list((tmp_path / "lods").glob("*.npz"))) == 1
    monkeypatch.setattr(type(body), "_decimated", lambda *_: pytest.fail("decimated again"))
    again = body.tracking_lod(1500)
    monkeypatch.undo()
    fresh = body._decimated(1500)
    for lod in (first, again):
        for name in ("vertices", "triangles", "skin_indices", "skin_weights"):
            np.testing.assert_array_equal(getattr(lod, name), fresh[name])
    assert again.name == first.name and again.metadata["lod_triangles"] == len(fresh["triangles"])
    monkeypatch.setenv("SWARMPOSE_CACHE_DIR", str(tmp_path))
    body.tracking_lod(1000)
    assert len(list((tmp_path / "lods").glob("*.npz"))) == 2


def test_build_is_memoised_and_deterministic():
    shape = BodyShape(height=1.7, leg_girth=1.1)
    first = build_parametric_body(shape)
    assert build_parametric_body(shape) is first
    fresh = build_parametric_body.__wrapped__(shape)
    np.testing.assert_array_equal(fresh.vertices, first.vertices)
    np.testing.assert_array_equal(fresh.skin_weights, first.skin_weights)


# ---------------------------------------------------------------------------- parsing
def test_parse_shape_presets_and_overrides():
    for name, shape in BUILTIN_PRESETS.items():
        assert parse_shape(name) == shape
    assert parse_shape("height=1.82,torso=1.1,arms=0.9,legs=1.0,sex=male") == BodyShape(1.82, 1.1, 0.9, 1.0, "male")
    assert parse_shape("female,height=1.60") == BodyShape(1.60, 1.0, 1.0, 1.0, "female")
    assert parse_shape(" male-heavy , legs = 1.5 ").leg_girth == 1.5
    assert parse_shape("torso_girth=1.2").torso_girth == 1.2
    assert parse_shape("") == BodyShape()
    shape = BodyShape(1.66, 1.2, 0.8, 1.1, "female")
    spec = (f"height={shape.height},torso={shape.torso_girth},arms={shape.arm_girth},"
            f"legs={shape.leg_girth},sex={shape.sex}")
    assert parse_shape(spec) == shape


@pytest.mark.parametrize("spec, needle", [
    ("giant", "male-heavy"),  # unknown preset lists the valid ones
    ("height=1.8,weight=80", "torso"),  # unknown key lists the valid ones
    ("height=tall", "not a number"),
    ("height=2.5", "1.2..2.3"),
    ("arms=0.3", "0.5..2.0"),
    ("legs=2.5", "leg_girth"),
    ("sex=other", "neutral"),
    ("height=1.8,female", "preset"),
])
def test_parse_shape_errors_name_the_fix(spec, needle):
    with pytest.raises(ConfigError, match=needle):
        parse_shape(spec)


def test_body_shape_validates():
    with pytest.raises(ConfigError, match="height 1.0"):
        BodyShape(height=1.0)
    with pytest.raises(ConfigError, match="torso_girth"):
        BodyShape(torso_girth=0.4)
    with pytest.raises(ConfigError, match="resolution"):
        build_parametric_body(BodyShape(), resolution=0.5)
    assert BodyShape(height=2) == BodyShape(height=2.0) and isinstance(BodyShape(height=2).height, float)
