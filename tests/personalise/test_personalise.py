"""Personalisation: key frames, the bone-length term and its noise-debiased lengths, the
volume-matched fitting body, and a whole fit on a synthetic subject whose true shape is known
(the oracle: the subject's own MakeHuman body)."""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import MAKEHUMAN, ValidatingSink, makehuman_walk, needs_assets

from swarmpose.body.shape_space import match_volume
from swarmpose.personalise.personalise import MAX_CORRECTION, bone_energy, debiased_length, spread_frames


def test_key_frames_are_spread_over_the_poses():
    poses = np.zeros((10, 36))
    poses[:, 3] = 1.0
    poses[:5, 7] = np.linspace(0.0, 0.04, 5)   # five nearly equal poses
    poses[5:, 7] = np.linspace(1.0, 2.0, 5)    # five far apart
    chosen = spread_frames(list(poses), 3)
    assert chosen == [0, 5, 9]
    assert spread_frames(list(poses[:2]), 5) == [0, 1]


@needs_assets
def test_bone_energy_is_the_mean_length_difference_in_cm():
    from swarmpose.body.loader import load_body

    body = load_body(f"makehuman:{MAKEHUMAN}", "male")
    exact = {(a, b): float(np.linalg.norm(body.point(a) - body.point(b)))
             for a, b in (("left_shoulder", "left_elbow"), ("right_knee", "right_ankle"))}
    assert bone_energy(body, exact) == pytest.approx(0.0, abs=1e-9)
    off = {bone: length + (0.01 if i == 0 else -0.03) for i, (bone, length) in enumerate(exact.items())}
    assert bone_energy(body, off) == pytest.approx(2.0)  # (1 cm + 3 cm) / 2
    assert bone_energy(body, {}) == 0.0


def test_debiased_length_by_hand():
    """m = 1.0, MAD = 0.05, so v = (1.4826 * 0.05)^2 and L = m - k v / (2 m); a spread too large
    for the first-order correction is capped at MAX_CORRECTION of m; no length: NaN."""
    lengths = np.array([0.9, 1.0, 1.1, np.nan, 1.05, 0.95])  # median 1.0, |deviations| .1 .1 .05 .05 0
    v = (1.4826 * 0.05) ** 2
    assert debiased_length(lengths, 1.0) == pytest.approx(1.0 - v / 2.0, abs=1e-12)
    assert debiased_length(lengths, 2.0) == pytest.approx(1.0 - v, abs=1e-12)
    assert debiased_length(lengths, 0.0) == pytest.approx(1.0, abs=1e-12)  # the plain median
    assert debiased_length(np.array([0.1, 1.0, 1.9]), 2.0) == pytest.approx(1.0 - MAX_CORRECTION)
    assert np.isnan(debiased_length(np.array([np.nan, np.nan])))


def _noisy_lengths(rng, length, sigma, frames, axes):
    """Monte-Carlo observed lengths (frames,) of a bone of ``length`` m whose two ends get Gaussian
    noise of ``sigma`` m on the first ``axes`` camera axes (2: the image plane; 3: isotropic) and
    whose direction turns within the image plane from frame to frame."""
    angle = rng.uniform(0.0, 2.0 * np.pi, frames)
    bone = length * np.stack([np.cos(angle), np.sin(angle), np.zeros(frames)], axis=1)
    noise = np.zeros((2, frames, 3))
    noise[..., :axes] = rng.normal(0.0, sigma, (2, frames, axes))
    return np.linalg.norm(bone + noise[1] - noise[0], axis=1)


def test_debiased_length_removes_the_lengthening_by_noise_monte_carlo():
    """Known L = 25 cm, 1.5 cm of noise per axis on each end (2.1 cm on the difference): the
    median comes out long by about var/(2L) per axis across the bone; the debiased length,
    with as many noise axes across the bone as the noise has, is within 0.2 mm of L (the median's
    Monte-Carlo error here is about 0.05 mm)."""
    rng = np.random.default_rng(7)
    true, sigma, frames = 0.25, 0.015, 200_000
    excess = 2 * sigma**2 / (2 * true)  # one axis across the bone, difference variance 2 sigma^2
    planar = _noisy_lengths(rng, true, sigma, frames, axes=2)
    assert np.median(planar) - true == pytest.approx(excess, abs=2e-4)
    assert debiased_length(planar, 1.0) == pytest.approx(true, abs=2e-4)
    spatial = _noisy_lengths(rng, true, sigma, frames, axes=3)
    assert np.median(spatial) - true == pytest.approx(2 * excess, abs=2e-4)
    assert debiased_length(spatial, 2.0) == pytest.approx(true, abs=2e-4)
    swapped = planar.copy()  # 5 % of frames measure some other pair of keypoints
    swapped[::20] = rng.uniform(0.0, 1.0, swapped[::20].size)
    assert debiased_length(swapped, 1.0) == pytest.approx(true, abs=1.5e-3)


@dataclass(frozen=True)
class _Mesh:
    """The two fields of a body that match_volume reads."""

    vertices: np.ndarray
    triangles: np.ndarray


def _icosahedron() -> _Mesh:
    t = (1.0 + 5.0**0.5) / 2.0
    v = np.array([(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
                  (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)], float)
    f = np.array([(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
                  (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
                  (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)])
    return _Mesh(v / np.linalg.norm(v[0]), f)


def test_match_volume_moves_the_vertices_out_along_their_normals_to_the_full_volume():
    """Oracle by hand: a unit icosahedron's vertex normals are radial, so moving every vertex out
    by d scales it by 1 + d; to enclose the volume of the same icosahedron scaled by 1.1, d = 0.1.
    The winding does not matter, and a larger mesh is shrunk."""
    ico = _icosahedron()
    big = _Mesh(1.1 * ico.vertices, ico.triangles)
    for mesh in (ico, _Mesh(ico.vertices, ico.triangles[:, ::-1].copy())):
        matched = match_volume(mesh, big, iterations=8)
        np.testing.assert_allclose(matched.vertices, 1.1 * ico.vertices, atol=1e-6)
    np.testing.assert_allclose(match_volume(big, ico, iterations=8).vertices, ico.vertices, atol=1e-6)


@needs_assets
def test_the_makehuman_fitting_body_encloses_the_full_bodys_volume():
    """The decimated tracking body encloses about 2 % less than the full mesh; the fitting body
    the same volume (divergence theorem, numpy), with the same bones and points."""
    from swarmpose.body.shape_space import MakeHumanSpace
    from swarmpose.personalise.personalise import body_measures

    space = MakeHumanSpace(MAKEHUMAN)
    x = space.start
    x[3] = 0.9  # heavy
    full, tracking, fitting = space.full_body(x), space.tracking_body(x), space.fitting_body(x)
    volume = body_measures(full)["volume_l"]
    assert body_measures(tracking)["volume_l"] < 0.99 * volume
    assert body_measures(fitting)["volume_l"] == pytest.approx(volume, rel=5e-4)
    assert len(fitting.vertices) == len(tracking.vertices)
    moved = np.linalg.norm(fitting.vertices - tracking.vertices, axis=1)
    assert 0.0003 < moved.mean() < 0.003  # a decimation's corners: about a millimetre
    np.testing.assert_array_equal(fitting.point_rest, tracking.point_rest)
    np.testing.assert_array_equal(fitting.bone_heads, tracking.bone_heads)


@pytest.fixture(scope="module")
def tall_walk(tmp_path_factory):
    return makehuman_walk(tmp_path_factory, "male-tall", 16)


def _first_hit_z(origin_dir: np.ndarray, vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Depth (z, m) of the nearest triangle a ray from the camera centre along ``origin_dir`` (3,),
    z = 1, hits (Möller-Trumbore over every triangle, numpy); 0 when none."""
    a, b, c = vertices[triangles[:, 0]], vertices[triangles[:, 1]], vertices[triangles[:, 2]]
    e1, e2 = b - a, c - a
    p = np.cross(origin_dir, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = -a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ origin_dir) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return float(t[hit].min()) if np.any(hit) else 0.0


@needs_assets
def test_model_depth_is_the_first_hit_of_each_pixel_ray():
    """The body's rendered depth against a numpy ray-triangle intersection at sampled pixels."""
    from swarmpose.body.loader import load_body
    from swarmpose.core.camera import Intrinsics
    from swarmpose.personalise.lift_bias import model_depth

    body = load_body(f"makehuman:{MAKEHUMAN}", "female").tracking_lod(1500)
    k = Intrinsics(width=160, height=120, fx=140.0, fy=140.0, cx=79.5, cy=59.5)
    pose = body.rest_pose(translation=(0.0, 0.0, 3.0), quaternion=(0.0, 1.0, 0.0, 0.0))  # upright, facing the camera
    depth = model_depth(body, pose, k)
    verts = body.pose(pose[None], "dqs")[0]
    rng = np.random.default_rng(3)
    inside = np.argwhere(depth > 0)
    assert len(inside) > 300  # the person covers part of the image
    picks = np.vstack([inside[rng.choice(len(inside), 12, replace=False)], [[0, 0], [5, 150]]])
    for row, col in picks:
        ray = np.array([(col - k.cx) / k.fx, (row - k.cy) / k.fy, 1.0])
        assert depth[row, col] == pytest.approx(_first_hit_z(ray, verts, np.asarray(body.triangles)), abs=1e-4)


@pytest.mark.slow
@needs_assets
def test_lift_bias_on_the_model_is_the_lifts_own_lengthening_on_the_observed_frames(tall_walk):
    """Oracle: the ground-truth 2D joints of a synthetic walk lifted on its observed (noisy) depth
    give each limb a length other than the true rest length; lift_bias, measured on the true body's
    own noise-free render at the true poses, predicts that difference (within 0.5 cm per limb and
    0.2 cm on average over the limbs: the observation has sensor noise and a room, the model none)."""
    from swarmpose.body.loader import load_body
    from swarmpose.personalise.lift_bias import LIMB_BONES, lift_bias, typical_depth
    from swarmpose.sources.registry import open_source
    from swarmpose.tracking.body_tracker import observed_depth
    from swarmpose.tracking.lift import lift_keypoints

    body = load_body(f"makehuman:{MAKEHUMAN}", "male-tall")
    truth = [json.loads(line) for line in (tall_walk / "groundtruth.jsonl").read_text().splitlines()]
    source = open_source(str(tall_walk))
    frames = list(source)
    source.close()
    poses = [np.array(t["pose"]) for t in truth]
    seen = {bone: [] for bone in LIMB_BONES}
    for frame, t in zip(frames, truth):
        points = {n: (xy[0], xy[1], 1.0) for n, xy in t["joints2d"].items() if xy is not None}
        lifted = lift_keypoints(observed_depth(frame.depth), frame.intrinsics, points)
        for a, b in LIMB_BONES:
            if np.all(np.isfinite(lifted[a])) and np.all(np.isfinite(lifted[b])):
                seen[(a, b)].append(np.linalg.norm(lifted[a] - lifted[b]))
    measured = {(a, b): np.median(v) - np.linalg.norm(body.point(a) - body.point(b)) for (a, b), v in seen.items()}
    predicted = lift_bias(body, poses, [typical_depth(f) for f in frames], frames[0].intrinsics)
    assert set(predicted) == set(LIMB_BONES)
    diff = np.array([predicted[bone] - measured[bone] for bone in LIMB_BONES])
    assert np.all(np.abs(diff) < 0.005), diff
    assert abs(diff.mean()) < 0.002, diff
    assert np.ptp(list(measured.values())) > 0.003  # the lift's error differs between limbs: not a trivial pass
    zero = -np.array([measured[bone] for bone in LIMB_BONES])  # the same checks on a prediction of no bias
    assert np.any(np.abs(zero) >= 0.005) or abs(zero.mean()) >= 0.002, f"no bias at all would pass: {zero}"


@needs_assets
def test_the_lifted_joints_lie_farther_in_front_of_a_heavier_bodys_joints():
    """The bias the fit's E_J 3D term carries (personalise's docstring): the lift pushes every
    keypoint's surface depth back by one radius per joint whatever the body, so its error depends
    on the build. Oracle: each body's own joints against their lift on its ray-cast render (the
    same pose, facing the camera at 3 m, no noise). The heavy body's hips and shoulders lift at
    least 1 cm farther in front of their joints than the slim body's."""
    from swarmpose.body.loader import load_body
    from swarmpose.core.camera import Intrinsics
    from swarmpose.personalise.lift_bias import model_depth
    from swarmpose.tracking.lift import lift_keypoints, median_depth

    k = Intrinsics(width=320, height=240, fx=285.0, fy=285.0, cx=159.5, cy=119.5)
    names = ("left_hip", "right_hip", "left_shoulder", "right_shoulder")
    error = {}
    for shape in ("female-slim", "female-heavy"):
        body = load_body(f"makehuman:{MAKEHUMAN}", shape)
        pose = body.rest_pose(translation=(0.0, 0.0, 3.0), quaternion=(0.0, 1.0, 0.0, 0.0))
        depth = model_depth(body, pose, k)
        joints = body.posed_points(pose[None], names)[0]
        lifted = lift_keypoints(depth, k, {n: (float(u), float(v), 1.0) for n, (u, v) in zip(names, k.project(joints))},
                                typical_depth=median_depth(depth))
        error[shape] = np.array([lifted[n][2] - p[2] for n, p in zip(names, joints)])  # m, < 0: in front
    assert np.all(np.isfinite(error["female-heavy"])) and np.all(np.isfinite(error["female-slim"]))
    assert np.all(error["female-heavy"] - error["female-slim"] < -0.01), error


@needs_assets
def test_a_body_larger_than_the_person_costs_more_where_the_sensor_sees_the_wall_behind_it():
    """E_S charges every model pixel no observation within T confirms. Oracle: the slim male's own
    render (ray cast, no noise) 3 m in front of a wall at 4.5 m, at the pose the fit holds: his own
    shape costs less than the heavy one (weight 1). Before, a model pixel over the wall cost T
    whether the model covered it or not, so nothing charged the heavier body's extra width (on
    noise-free walks with the true poses held, the fit came out 16 % too large)."""
    from swarmpose.body.shape_space import shape_space_for
    from swarmpose.core.camera import Intrinsics
    from swarmpose.gpu.context import ClContext
    from swarmpose.personalise.lift_bias import model_depth
    from swarmpose.personalise.personalise import ShapeSample, _KeyFrame
    from swarmpose.sources.base import Frame
    from swarmpose.tracking.body_tracker import BodyTracker
    from swarmpose.tracking.config import TrackerConfig

    space = shape_space_for(f"makehuman:{MAKEHUMAN}", None, 1500)
    slim, heavy = (space.clip(np.array([1.0, 1.0, 0.5, w, 0.5])) for w in (0.0, 1.0))
    k = Intrinsics(width=320, height=240, fx=285.0, fy=285.0, cx=159.5, cy=119.5)
    pose = space.full_body(slim).rest_pose(translation=(0.0, 0.0, 3.0), quaternion=(0.0, 1.0, 0.0, 0.0))
    depth = model_depth(space.full_body(slim), pose, k)
    depth = np.where(depth > 0, depth, np.float32(4.5))
    config, context = TrackerConfig(), ClContext.for_spec("cpu")
    body = space.fitting_body(slim)
    key = _KeyFrame(ShapeSample(Frame(0, 0, depth, None, k), None, pose), body, k, config, (96, 96), context,
                    BodyTracker(body, k, config, context))
    own, heavier = key.energy(space.fitting_body(slim)), key.energy(space.fitting_body(heavy))
    assert heavier > own + 5.0, (own, heavier)  # measured: 533.7 against 544.1; with the old E_S 531.1 against 532.4


@pytest.mark.slow
@needs_assets
def test_personalize_recovers_a_tall_subjects_height_and_writes_a_body_that_loads(tall_walk, tmp_path, capsys):
    """The start body is 1.68 m; the subject 1.93 m. On this test's small budget (16 frames,
    tracking and pose refits at p = g = 24, 2 rounds) the fit must land within 4 cm of the true
    height and 12 % of the volume (the start body is 25 cm and about 25 % off; the issue's 2 cm /
    5 % goal is measured at the defaults by scripts/bench-personalise.sh), and the GLB must load
    as --body with its parameters."""
    from swarmpose.body.loader import load_body
    from swarmpose.cli.main import main
    from swarmpose.personalise.personalise import body_measures
    from swarmpose.personalise.shape_stature import BAND

    glb = tmp_path / "me.glb"
    code = main(["personalize", str(tall_walk), "--body", f"makehuman:{MAKEHUMAN}", "--frames", "16",
                 "--particles", "24", "--generations", "24", "--keyframes", "8", "--rounds", "2",
                 "--out", str(glb), "--json", "--quiet"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    truth = body_measures(load_body(f"makehuman:{MAKEHUMAN}", "male-tall"))
    fitted = load_body(str(glb))
    assert abs(fitted.height - truth["height_m"]) < 0.04, (fitted.height, truth)
    assert report["height_m"] == pytest.approx(fitted.height, abs=1e-3)
    # the stature term: measured on the depth, it bounds the fitted height (its band, plus 1 cm)
    assert report["stature_frames"] >= 3
    assert report["stature_measured_m"] == pytest.approx(truth["height_m"], rel=0.03)
    assert report["height_m"] <= report["stature_measured_m"] * (1 + BAND[1]) + 0.01, report
    assert abs(report["volume_l"] / truth["volume_l"] - 1) < 0.12, (report["volume_l"], truth)
    assert fitted.metadata["personalised"]["parameters"] == report["parameters"]
    assert set(report["parameters"]) == {"gender", "caucasian", "muscle", "weight", "height"}
    assert report["own_pose_shapes_judged"] >= 5  # the last stage ran a round: 5 sliders, each moved one way at least


@pytest.mark.slow
@needs_assets
def test_personalize_own_pose_candidates_0_skips_the_last_stage(tall_walk, tmp_path, capsys):
    from swarmpose.cli.main import main

    assert main(["personalize", str(tall_walk), "--body", f"makehuman:{MAKEHUMAN}", "--frames", "6", "--particles",
                 "8", "--generations", "8", "--keyframes", "3", "--rounds", "1", "--own-pose-candidates", "0",
                 "--out", str(tmp_path / "me.glb"), "--json", "--quiet"]) == 0
    assert json.loads(capsys.readouterr().out)["own_pose_shapes_judged"] == 0


@pytest.mark.slow
@needs_assets
def test_personalize_refuses_a_fixed_body_and_a_recording_without_a_person(tall_walk, tmp_path, capsys):
    from swarmpose.cli.main import main

    assert main(["personalize", str(tall_walk), "--body", str(tmp_path / "x.glb"), "--out",
                 str(tmp_path / "me.glb"), "--quiet"]) == 2
    assert "no shape parameters" in capsys.readouterr().err
    mkv = MAKEHUMAN.parents[1] / "rgbd" / "azure_kinect_one_frame" / "recording.mkv"
    movenet = MAKEHUMAN.parents[1] / "pose2d" / "movenet_singlepose_lightning.onnx"
    assert main(["personalize", f"mkv:{mkv}", "--body", f"makehuman:{MAKEHUMAN}", "--detector", f"onnx:{movenet}",
                 "--frames", "1", "--out", str(tmp_path / "me.glb"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "no person was tracked" in err and not (tmp_path / "me.glb").exists()
    assert main(["personalize", str(tall_walk), "--body", f"makehuman:{MAKEHUMAN}", "--out",
                 str(tmp_path / "me.txt"), "--quiet"]) == 2
    assert ".glb" in capsys.readouterr().err


@pytest.fixture(scope="module")
def online_run(tall_walk, tmp_path_factory):
    """One worker run of ``--personalize 10`` over the tall walk's 16 frames, publishing to a
    validating sink and writing the replay files (the fit takes most of its 100 s, so the tests
    of what the run says and writes share it): the sink, the parts, the start body, the
    personalisation the worker reported before any frame, the info message after the run and
    the output folder."""
    from contextlib import ExitStack
    from types import SimpleNamespace

    from swarmpose.messages import validate
    from swarmpose.messages.build import info_message
    from swarmpose.pipeline.config import ServiceConfig
    from swarmpose.pipeline.service import open_parts
    from swarmpose.pipeline.worker import Worker
    from swarmpose.sources.registry import open_source
    from swarmpose.tracking.config import TrackerConfig

    uri = f"folder:{tall_walk}"
    out = tmp_path_factory.mktemp("online")
    config = ServiceConfig(source=uri, body=f"makehuman:{MAKEHUMAN}", overlay=False,
                           tracker=TrackerConfig(personalize=10, particles=16, generations=16, max_people=1))
    sink = ValidatingSink()
    with ExitStack() as stack:
        parts = open_parts(config, stack, out=str(out))
        start = parts.body  # taken before the run, whatever the run does to the parts
        worker = Worker(lambda: open_source(uri), parts.pipeline, [sink, *parts.sinks], camera="test",
                        drop_stale=False, source_uri=uri, status_period_s=0.1, source=parts.source)
        before = worker.stats.personalisation
        worker.run()
        info = validate(info_message("test", body=parts.pipeline.tracker.body, body_spec=config.body,
                                     personalisation=parts.pipeline.personalisation))
    return SimpleNamespace(sink=sink, parts=parts, start=start, before=before, info=info, out=out)


@pytest.mark.slow
@needs_assets
def test_personalize_n_locks_each_bodys_shape_online_and_status_and_info_say_so(online_run):
    """`--personalize 10` on a worker run: statuses go from collecting to locked with the fitted
    parameters (valid against the schemas), the tracker then tracks with the fitted body, and
    the info message carries the same state."""
    sink = online_run.sink
    assert online_run.before == {"needed": 10, "bodies": []}  # before any frame
    states = [(s["tracker"].get("personalisation", {}).get("bodies") or [{}])[0].get("state")
              for s in sink.statuses]  # before the first frame: personalisation on, no body yet
    assert "collecting" in states and states[-1] == "locked", states
    locked = sink.statuses[-1]["tracker"]["personalisation"]["bodies"][0]
    assert locked["frames"] == locked["needed"] == 10
    assert abs(locked["height_m"] - 1.929) < 0.06, locked  # the start body is 1.68 m
    tracker = online_run.parts.pipeline.tracker
    assert tracker.body.height == pytest.approx(locked["height_m"], abs=0.01)  # tracking LOD of the fit
    assert online_run.info["body"]["personalisation"]["bodies"][0]["parameters"] == locked["parameters"]
    assert len(sink.frames) == 16 and all(m["bodies"] for m in sink.frames)


@needs_assets
def test_personalize_n_writes_the_bvh_of_the_locked_body(online_run):
    """`--personalize 10 --out DIR`: poses.bvh animates the fitted body, not the start body:
    its offsets are the locked rig's bones and a row written before the lock places the
    joints (read back with the third-party bvhio) where the numpy FK of that frame's pose on the
    locked rig does."""
    import bvhio

    from swarmpose.body.kinematics import forward_kinematics
    from swarmpose.motion.bvh import read_bvh
    from swarmpose.publish.bvh_file import bvh_transform

    parts, out = online_run.parts, online_run.out
    locked = parts.pipeline.tracker.body
    assert parts.pipeline.tracker.personalisation()["state"] == "locked"
    assert abs(locked.height - online_run.start.height) > 0.05  # a 1.93 m subject, a 1.68 m start body
    clip = read_bvh(out / "poses.bvh")
    names, parents, heads = locked.bone_names, locked.rig.parents, locked.rig.heads
    assert len(clip) == len(online_run.sink.frames) == 16
    for b in range(1, len(names)):
        np.testing.assert_allclose(clip.offsets[clip.joint_index(names[b])], 100.0 * (heads[b] - heads[parents[b]]),
                                   atol=1e-4, err_msg=names[b])
    root = bvhio.readAsHierarchy(str(out / "poses.bvh"))
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    first = json.loads((out / "poses.jsonl").read_text().splitlines()[0])
    _, expected = forward_kinematics(locked.rig, np.array([first["bodies"][0]["pose"]]))
    to_bvh = bvh_transform(first)
    root.loadPose(0)
    got = np.array([list(joints[n].PositionWorld) for n in names])
    np.testing.assert_allclose(got, 100.0 * (expected[0] @ to_bvh[:3, :3].T + to_bvh[:3, 3]), atol=0.05)


@pytest.mark.slow
def test_personalize_fits_the_builtin_bodys_height_and_girths(tmp_path, capsys):
    """A built-in male-heavy subject (1.78 m, torso girth 1.35, arms and legs 1.25) from the
    average built-in body (1.75 m, girths 1.0): height within 4 cm and every girth found
    thicker than the start, on a small budget (the oracle: the preset's own numbers); the last
    stage is MakeHuman's only, so it does not run here."""
    from swarmpose.body.parametric_shape import BUILTIN_PRESETS
    from swarmpose.cli.main import main

    seq = tmp_path / "heavy"
    assert main(["synth", "--body", "builtin", "--shape", "male-heavy", "--motion", "builtin:walk", "--frames", "12",
                 "--out", str(seq), "--quiet"]) == 0
    capsys.readouterr()  # synth's own lines
    assert main(["personalize", str(seq), "--body", "builtin", "--shape", "male", "--frames", "12", "--particles",
                 "24", "--generations", "24", "--keyframes", "6", "--rounds", "1", "--out", str(tmp_path / "me.glb"),
                 "--json", "--quiet"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["own_pose_shapes_judged"] == 0  # MakeHuman's stage only
    truth = BUILTIN_PRESETS["male-heavy"]
    assert abs(report["height_m"] - truth.height) < 0.04, report
    assert "sex=male" in report["shape"]
    for name in ("torso", "arms", "legs"):
        assert report["parameters"][name] > 1.08, report["parameters"]


def test_personalize_needs_at_least_three_frames():
    from swarmpose.core.errors import ConfigError
    from swarmpose.tracking.config import TrackerConfig

    with pytest.raises(ConfigError, match="at least 3"):
        TrackerConfig(personalize=2)
    assert TrackerConfig(personalize=0).personalize == 0 and TrackerConfig(personalize=3).personalize == 3


@needs_assets
def test_a_failed_fit_is_reported_valid_and_a_new_person_starts_again_from_the_start_body():
    """A fit with too few usable frames fails with its reason (valid in a status message); a
    tracker reused for another person takes the start body back and collects again."""
    from swarmpose.body.makehuman_macros import PRESET_MACROS
    from swarmpose.body.shape_space import MakeHumanSpace
    from swarmpose.core.camera import Intrinsics
    from swarmpose.messages import validate
    from swarmpose.personalise.online_personalise import personalising_tracker
    from swarmpose.pipeline.status import WorkerStats, status_message
    from swarmpose.tracking.config import TrackerConfig

    space = MakeHumanSpace(MAKEHUMAN)
    tracker = personalising_tracker(space, 3, Intrinsics(320, 240, 280.0, 280.0, 160.0, 120.0),
                                    TrackerConfig(personalize=3, particles=8, generations=8), body_id=4)
    tracker.fitting.personalise(tracker)  # no samples at all
    state = tracker.personalisation()
    assert state["state"] == "failed" and "0 of 0 frames" in state["reason"] and state["id"] == 4
    stats = WorkerStats()
    stats.update(personalisation={"needed": 3, "bodies": [state]})
    validate(status_message("t", "running", stats, 1.0, 1.0, source_uri="x", source_state="running",
                            detector_spec="simulated", zenoh=None, opencl_device="", errors=[]))

    heavy = space.tracking_body(PRESET_MACROS["male-heavy"].vector())
    tracker.set_body(heavy)
    tracker.fitting.state = "locked"
    tracker.new_person()
    assert tracker.personalisation() == {"id": 4, "state": "collecting", "frames": 0, "needed": 3}
    np.testing.assert_allclose(tracker.body.vertices, space.tracking_body(space.start).vertices)
    np.testing.assert_allclose(tracker.objective.scorer.body.vertices, tracker.body.vertices)


@pytest.mark.slow
@needs_assets
def test_with_other_people_in_view_a_frame_whose_person_is_half_hidden_is_not_collected(tall_walk):
    """Oracle: the walk's own depth with the person's pixels below the hips removed (as another
    person's pixels are in a several-people run). The hidden share the tracker measures is the
    share of the person's pixels removed, counted on the depth by hand (within 0.1); such a frame
    is not collected while other people are in view, the whole frame is, and with one person in
    view (no depth removed for others), or when the tracker scores no depth, the check does not run."""
    from dataclasses import replace

    from swarmpose.body.shape_space import MakeHumanSpace
    from swarmpose.detect.registry import make_detector
    from swarmpose.personalise.online_personalise import MAX_HIDDEN_SHARE, hidden_share, personalising_tracker
    from swarmpose.sources.registry import open_source
    from swarmpose.tracking.config import TrackerConfig

    source = open_source(str(tall_walk))
    frames = list(source)
    detector = make_detector("simulated", source)
    joints = [detector.detect(f) for f in frames[:3]]
    source.close()
    truth = [json.loads(line) for line in (tall_walk / "groundtruth.jsonl").read_text().splitlines()]
    tracker = personalising_tracker(MakeHumanSpace(MAKEHUMAN), 100, frames[0].intrinsics,
                                    TrackerConfig(personalize=100, particles=16, generations=16, max_people=1))
    tracker.step(frames[0], joints[0], others_removed=True)
    assert len(tracker.fitting.samples) == 1  # the whole person in view

    frame, t = frames[1], truth[1]
    xy = np.array([p for p in t["joints2d"].values() if p is not None])
    hips_row = int(round(np.mean([t["joints2d"]["left_hip"][1], t["joints2d"]["right_hip"][1]])))
    u0, u1 = int(xy[:, 0].min()) - 40, int(xy[:, 0].max()) + 40
    v0, v1 = int(xy[:, 1].min()) - 30, int(xy[:, 1].max()) + 15
    depth = np.nan_to_num(np.asarray(frame.depth, float))
    centre = np.median(depth[hips_row - 20:hips_row + 20, int(xy[:, 0].mean()) - 5:int(xy[:, 0].mean()) + 5])
    person = np.zeros(depth.shape, bool)
    person[v0:v1, u0:u1] = np.abs(depth[v0:v1, u0:u1] - centre) < 0.5
    removed = person.copy()
    removed[:hips_row] = False
    expected = removed.sum() / person.sum()
    half = replace(frame, depth=np.where(removed, 0.0, depth).astype(np.float32))
    tracker.step(half, joints[1], others_removed=True)
    share = hidden_share(tracker)
    assert abs(share - expected) < 0.1, (share, expected)
    assert share > MAX_HIDDEN_SHARE and len(tracker.fitting.samples) == 1
    tracker.step(half, joints[1], others_removed=False)  # one person in view: no check
    assert len(tracker.fitting.samples) == 2
    tracker.step(frames[2], joints[2], others_removed=True)
    assert hidden_share(tracker) < MAX_HIDDEN_SHARE and len(tracker.fitting.samples) == 3
    joints_only = personalising_tracker(MakeHumanSpace(MAKEHUMAN), 100, frames[0].intrinsics,
                                        TrackerConfig(mode="joints", personalize=100, particles=16, generations=16))
    joints_only.step(half, joints[1], others_removed=True)  # scores no depth: nothing to judge hiding by
    assert len(joints_only.fitting.samples) == 1
